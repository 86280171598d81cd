#!/usr/bin/env python3
"""Summarise an MCAP recording of a run (``launch_cell.py --record``) and dump messages.

Usage: read_mcap.py RUN.mcap [--dump N] [--topic TOPIC ...] [--depth D]

Prints the file's profile, whether it is complete (a run killed without a clean shutdown
leaves no footer; its complete chunks are still read), then per topic: type, message count,
first and last log time (sim s) and rate. ``--dump N`` decodes the first N messages of each
(selected) topic with mcap_ros2's decoder, the ``ros2msg`` schema stored in the file.
"""
import argparse
from pathlib import Path
import struct
import sys
from typing import Dict, List

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Header, Message, Schema
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory


def _value(v, depth: int, indent: str) -> str:
    """Return a decoded message (or field) as indented ``name: value`` lines."""
    if hasattr(v, '__slots__') and not isinstance(v, (str, bytes)):
        if depth <= 0:
            return ' {...}'
        lines = [f'\n{indent}{k}:{_value(getattr(v, k), depth - 1, indent + "  ")}'
                 for k in v.__slots__]
        return ''.join(lines)
    if isinstance(v, (list, tuple)):
        if not v:
            return ' []'
        if all(not hasattr(x, '__slots__') for x in v):
            shown = ', '.join(f'{x:.6g}' if isinstance(x, float) else repr(x) for x in v[:8])
            return f' [{shown}{", ..." if len(v) > 8 else ""}]  ({len(v)})'
        if depth <= 0:
            return f' [{len(v)} items]'
        out = ''.join(f'\n{indent}- [{k}]{_value(x, depth - 1, indent + "  ")}'
                      for k, x in enumerate(v[:3]))
        return out + (f'\n{indent}  ... {len(v)} items' if len(v) > 3 else '')
    if isinstance(v, float):
        return f' {v:.9g}'
    return f' {v!r}'


def main(argv=None) -> int:
    """Print the file's summary and per-topic table, and dump messages if asked.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
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
    schemas: Dict[int, Schema] = {}
    channels: Dict[int, Channel] = {}
    counts: Dict[int, int] = {}
    first: Dict[int, int] = {}
    last: Dict[int, int] = {}
    dumps: Dict[int, List[str]] = {}
    decoders = DecoderFactory()
    header, complete, error = None, False, ''
    wanted = set(args.topic) if args.topic else None
    with open(args.path, 'rb') as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Header):
                    header = record
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                    counts.setdefault(record.id, 0)
                elif isinstance(record, Message):
                    cid = record.channel_id
                    counts[cid] = counts.get(cid, 0) + 1
                    first.setdefault(cid, record.log_time)
                    last[cid] = record.log_time
                    channel = channels[cid]
                    if args.dump and counts[cid] <= args.dump and (
                            wanted is None or channel.topic in wanted):
                        schema = schemas.get(channel.schema_id)
                        decode = decoders.decoder_for(channel.message_encoding, schema)
                        text = (_value(decode(record.data), args.depth, '    ') if decode
                                else f' ({len(record.data)} bytes, no decoder)')
                        dumps.setdefault(cid, []).append(
                            f'  #{counts[cid]} log {record.log_time * 1e-9:.3f} s'
                            f' publish {record.publish_time * 1e-9:.3f} s:{text}')
                elif isinstance(record, Footer):
                    complete = True
        except (McapError, EOFError, ValueError, struct.error) as exc:
            error = f'{type(exc).__name__}: {exc}'
    total = sum(counts.values())
    profile = header.profile if header else '?'
    state = 'complete' if complete else f'CUT SHORT (no footer; {error or "truncated"})'
    print(f'{args.path}: profile {profile!r}, {total} messages on {len(channels)} channels, '
          f'{state}')
    name_width = max([len(c.topic) for c in channels.values()] + [5])
    print(f'{"topic":<{name_width}}  {"type":<38} {"count":>7} {"first s":>9} {"last s":>9} '
          f'{"rate Hz":>8}')
    for cid, channel in sorted(channels.items(), key=lambda kv: kv[1].topic):
        if wanted is not None and channel.topic not in wanted:
            continue
        schema = schemas.get(channel.schema_id)
        n = counts.get(cid, 0)
        t0 = first.get(cid)
        t1 = last.get(cid)
        span = (t1 - t0) * 1e-9 if n > 1 else 0.0
        rate = f'{(n - 1) / span:8.1f}' if span > 0 else f'{"":>8}'
        times = (f'{t0 * 1e-9:9.3f} {t1 * 1e-9:9.3f}' if n else f'{"-":>9} {"-":>9}')
        print(f'{channel.topic:<{name_width}}  {schema.name if schema else "?":<38} {n:>7} '
              f'{times} {rate}  [{channel.message_encoding}/'
              f'{schema.encoding if schema else "-"}]')
    for cid, lines in sorted(dumps.items(), key=lambda kv: channels[kv[0]].topic):
        print(f'\n{channels[cid].topic}:')
        print('\n'.join(lines))
    return 0 if complete else 3


if __name__ == '__main__':
    sys.exit(main())
