"""An interface without a PyPI wheel is present only where its type support loads.

Absent (not installed, or installed but not loading) it is ``None`` with the reason, and the
node says so: a note if it is not installed, a warning naming it if it does not load. With
another venv's libraries (a real load failure) in ``test_environment.py``.
"""
import sys
import types

from rosidl_generator_py.import_type_support_impl import UnsupportedTypeSupport

from scara_collab.nodes.optional_interfaces import optional_interface


class Logger:
    """Keep what a node's logger is told, by level."""

    def __init__(self):
        """Nothing said yet."""
        self.said = []

    def info(self, text):
        """Keep a note."""
        self.said.append(('info', text))

    def warning(self, text):
        """Keep a warning."""
        self.said.append(('warning', text))


def test_a_type_whose_support_loads_is_present():
    """A wheel's message type is present, and nothing is said for it."""
    from std_msgs.msg import String
    found = optional_interface('std_msgs.msg', 'String')
    assert found.type is String and found.reason == '' and found.name == 'std_msgs/msg/String'
    log = Logger()
    found.say_absent(log, 'nothing')
    assert log.said == []


def test_a_package_not_installed_is_absent_with_a_note():
    """A missing package: absent, a note on how to build it."""
    found = optional_interface('no_such_msgs.action', 'Nothing')
    assert found.type is None and not found.installed
    log = Logger()
    found.say_absent(log, 'no action')
    assert log.said == [('info', 'no_such_msgs/action/Nothing: no_such_msgs is not installed '
                         '(./scripts/build_interfaces builds it); no action')]


def test_a_type_whose_support_does_not_load_is_absent_with_a_warning(monkeypatch):
    """Importable, but its C type support fails: absent, a warning with the library missing."""

    class Meta(type):
        _TYPE_SUPPORT = None

        @classmethod
        def __import_type_support__(cls):
            try:
                raise ImportError('libbroken_msgs__rosidl_generator_py.so: cannot open shared '
                                  'object file: No such file or directory')
            except ImportError:
                raise UnsupportedTypeSupport('broken_msgs')

    package = types.ModuleType('broken_msgs')
    package.__path__ = []
    msg = types.ModuleType('broken_msgs.msg')
    msg.Broken = Meta('Broken', (), {})
    monkeypatch.setitem(sys.modules, 'broken_msgs', package)
    monkeypatch.setitem(sys.modules, 'broken_msgs.msg', msg)
    found = optional_interface('broken_msgs.msg', 'Broken')
    assert found.type is None and found.installed
    log = Logger()
    found.say_absent(log, 'no /broken')
    assert log.said == [('warning', 'broken_msgs/msg/Broken: broken_msgs is installed but its '
                         'type support does not load (libbroken_msgs__rosidl_generator_py.so: '
                         'cannot open shared object file: No such file or directory); '
                         'no /broken')]
