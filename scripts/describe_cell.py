#!/usr/bin/env python3
"""Print the cell as the model module builds it from config/cell.yaml and the xacro files.

Usage: describe_cell.py [--profile slim|default|heavy] [--urdf FILE]
"""
import argparse
import sys

import numpy as np

from scara_collab.core.model import load_cell


def main(argv=None) -> int:
    """Print the arms, joints, links and bins of the cell (and write its URDF); return 0.

    :param argv: the command-line arguments (default ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--profile', default=None, help='slim, default or heavy')
    parser.add_argument('--urdf', default=None, help='also write the expanded cell URDF here')
    args = parser.parse_args(argv)
    cell = load_cell(args.profile)
    print(f'cell profile: {cell.profile}; reach {cell.reach_min}..{cell.reach_max} m; '
          f'margin {cell.safety_margin} m; belt {cell.belt.speed} m/s, {cell.belt.width} m wide')
    for arm in cell.arms:
        print(f'\n{arm.name}: base {np.round(arm.base_position, 3).tolist()}, '
              f'L1 {arm.l1} m, L2 {arm.l2} m, link radius {arm.link_radius} m')
        for j, name in enumerate(arm.joint_names):
            print(f'  {name:28s} [{arm.lower[j]:+.3f}, {arm.upper[j]:+.3f}]  '
                  f'v {arm.max_velocity[j]}  a {arm.max_acceleration[j]}  '
                  f'effort {arm.max_effort[j]}')
        for label, link in (('link 1', arm.link_1), ('link 2', arm.link_2),
                            ('quill', arm.quill)):
            print(f'  {label:7s} mass {link.mass:7.3f} kg  com {np.round(link.com, 3).tolist()}'
                  f'  I diag {np.round(np.diag(link.inertia), 4).tolist()} kg m^2')
    for (robot, cls), pos in sorted(cell.bins.items()):
        print(f'bin {robot}/{cls}: {np.round(pos, 3).tolist()}')
    if args.urdf:
        with open(args.urdf, 'w') as f:
            f.write(cell.urdf)
        print(f'\nwrote {args.urdf}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
