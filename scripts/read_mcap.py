#!/usr/bin/env python3
"""Summarise an MCAP recording of a run (``launch_cell.py --record``) and dump messages.

Usage: read_mcap.py RUN.mcap [--dump N] [--topic TOPIC ...] [--depth D]

Prints the file's profile, whether it is complete (a run killed without a clean shutdown
leaves no footer; its complete chunks are still read), then per topic: type, message count,
first and last log time (sim s) and rate. ``--dump N`` decodes the first N messages of each
(selected) topic with mcap_ros2's decoder (:func:`scara_collab.records.mcap_log.iter_messages`
reads the file).
"""
import argparse
from pathlib import Path
import sys

from mcap.reader import NonSeekingReader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from scara_collab.records.mcap_log import (iter_messages, MESSAGE_ENCODING, Reading,
                                           ros2msg_definition, SCHEMA_ENCODING)


def _value(v, depth: int, indent: str) -> str:
    """Return a decoded message (or field) as indented ``name: value`` lines."""
    if hasattr(v, '__slots__') and not isinstance(v, (str, bytes)):
        if depth <= 0:
            return ' {...}'
        return ''.join(f'\n{indent}{k}:{_value(getattr(v, k), depth - 1, indent + "  ")}'
                       for k in v.__slots__)
    if isinstance(v, (list, tuple)):
        if v and all(not hasattr(x, '__slots__') for x in v):
            shown = ', '.join(f'{x:.6g}' if isinstance(x, float) else repr(x) for x in v[:8])
            return f' [{shown}{", ..." if len(v) > 8 else ""}]  ({len(v)})'
        if not v or depth <= 0:
            return f' [{len(v)} items]'
        out = ''.join(f'\n{indent}- [{k}]{_value(x, depth - 1, indent + "  ")}'
                      for k, x in enumerate(v[:3]))
        return out + (f'\n{indent}  ... {len(v)} items' if len(v) > 3 else '')
    return f' {v:.9g}' if isinstance(v, float) else f' {v!r}'


def main(argv=None) -> int:
    """Print the file's summary and per-topic table, and dump messages if asked.

    :return: 0 for a complete file, 3 for one without a footer, 1 if there is no file.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('path', type=Path, help='the .mcap file (e.g. runs/<run>/run.mcap)')
    parser.add_argument('--dump', type=int, default=0, metavar='N',
                        help='print the first N decoded messages of each topic')
    parser.add_argument('--topic', action='append', default=None,
                        help='only this topic (repeatable)')
    parser.add_argument('--depth', type=int, default=4, help='nesting shown by --dump')
    args = parser.parse_args(argv)
    if not args.path.is_file():
        print(f'read_mcap: no such file: {args.path}', file=sys.stderr)
        return 1
    with open(args.path, 'rb') as f:
        profile = NonSeekingReader(f).get_header().profile
    topics, dumps, decoders, reading = {}, {}, {}, Reading()
    for msg in iter_messages(args.path, args.topic, reading):
        n, first, _, _ = topics.get(msg.topic, (0, msg.log_time, 0, ''))
        topics[msg.topic] = (n + 1, first, msg.log_time, msg.type)
        if n < args.dump:
            if msg.type not in decoders:
                schema = Schema(id=0, name=msg.type, encoding=SCHEMA_ENCODING,
                                data=ros2msg_definition(msg.type).encode())
                decoders[msg.type] = DecoderFactory().decoder_for(MESSAGE_ENCODING, schema)
            dumps.setdefault(msg.topic, []).append(
                f'  #{n + 1} log {msg.log_time * 1e-9:.3f} s:'
                + _value(decoders[msg.type](msg.data), args.depth, '    '))
    state = 'complete' if reading.complete else f'CUT SHORT (no footer; {reading.error})'
    print(f'{args.path}: profile {profile!r}, {sum(t[0] for t in topics.values())} messages '
          f'on {len(topics)} topics, {state}')
    width = max([len(t) for t in topics] + [5])
    print(f'{"topic":<{width}}  {"type":<38} {"count":>7} {"first s":>9} {"last s":>9} '
          f'{"rate Hz":>8}')
    for topic, (n, t0, t1, type_name) in sorted(topics.items()):
        rate = f'{(n - 1) / ((t1 - t0) * 1e-9):8.1f}' if t1 > t0 else ' ' * 8
        print(f'{topic:<{width}}  {type_name:<38} {n:>7} {t0 * 1e-9:9.3f} {t1 * 1e-9:9.3f} '
              f'{rate}')
    for topic, lines in sorted(dumps.items()):
        print(f'\n{topic}:\n' + '\n'.join(lines))
    return 0 if reading.complete else 3


if __name__ == '__main__':
    sys.exit(main())
