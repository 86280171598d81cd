"""The launcher's console: stage lines and progress on stdout, every line in ``launch.log``."""
from pathlib import Path
import sys
import time


class Console:
    """Stage lines and progress on stdout (and in ``launch.log``); errors always shown."""

    def __init__(self, log_path: Path, quiet: bool):
        """Append the lines to ``log_path``; ``quiet`` shows errors only on stdout."""
        self.quiet = quiet
        self.tty = sys.stdout.isatty()
        self.log = open(log_path, 'a', encoding='utf-8')
        self._live = False
        self._t0 = time.monotonic()

    def _clear_live(self) -> None:
        if self._live:
            sys.stdout.write('\r\x1b[K')
            self._live = False

    def say(self, text: str, error: bool = False) -> None:
        """Log ``text`` and print it unless quiet (an ``error`` is always printed)."""
        self.log.write(f'{time.monotonic() - self._t0:7.2f} {text}\n')
        self.log.flush()
        if self.quiet and not error:
            return
        self._clear_live()
        print(text, flush=True)

    def progress(self, text: str) -> None:
        """Show ``text`` as the live line on a terminal, else as a logged line."""
        if self.quiet:
            return
        if self.tty:
            sys.stdout.write('\r' + text + '\x1b[K')
            sys.stdout.flush()
            self._live = True
        else:
            self.say(text)

    def close(self) -> None:
        """End the live line and close the log file."""
        self._clear_live()
        self.log.close()
