"""Render a run folder as an animated GIF: the cell in PyBullet's headless camera.

The scene is :class:`scara_collab.sim.cell_sim.CellSim` (the cell URDF the bridge loads:
arms, belt, bins), built in its own DIRECT client and never stepped: each frame poses both
arms with :meth:`CellSim.reset_arm` and renders with ``getCameraImage(...,
renderer=ER_TINY_RENDERER)`` (software rendering, no display or GPU). The simulator's
collision-only bodies (the belt's rigid box, the floor plane) are replaced by a plain visual
floor so nothing flickers on the belt.

What moves comes from the run's files:

- the joints from ``timeseries.csv`` (every joint state of the run window);
- the items from ``run.mcap`` (``/conveyor/items``, recorded with ``--record``), if present;
  otherwise the arms only;
- a person in the cell from ``run.mcap``'s ``/person/markers`` (the bridge's ground truth:
  each message the whole body, cylinders with sphere ends), if the run had one;
- the counters in the caption from ``events.csv``.

The GIF is a time-lapse of the job window (``summary.json``): ``fps`` frames per second of
GIF, at most ``max_seconds`` of GIF (so a 120 s run at 10 fps and 30 s plays 4x fast), every
frame on one palette (Pillow) so only the changed pixels are stored.

Usage (a sketch, not a doctest: it needs a run folder)::

    render_gif('runs/20261122-053435_collaborative')   # -> .../run.gif
"""
import argparse
import math
from pathlib import Path
import sys
import time
from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np
from PIL import Image, ImageDraw, ImageFont
import pybullet

from scara_collab.core.config import load_config
from scara_collab.core.model import CellModel, load_cell
from scara_collab.records import report
from scara_collab.records.mcap_log import iter_messages, MCAP_FILE, Reading
from scara_collab.sim.cell_sim import CellSim

GIF_FILE = 'run.gif'
ITEMS_TOPIC = '/conveyor/items'
PERSON_TOPIC = '/person/markers'
FLOOR_RGBA = (0.78, 0.80, 0.82, 1.0)
BACKGROUND = (255, 255, 255)
CAPTION_HEIGHT = 24
_HIDDEN = (0.0, 0.0, -50.0)  # where unused item bodies wait, out of view


class Camera:
    """The view: what it looks at and from where.

    :param target: the point looked at (world, m).
    :param distance: from the target, m.
    :param yaw: deg (PyBullet's ``computeViewMatrixFromYawPitchRoll``).
    :param pitch: deg, negative looks down.
    :param fov: vertical field of view, deg.
    """

    def __init__(self, target=(2.0, 0.0, 0.2), distance: float = 5.6, yaw: float = -60.0,
                 pitch: float = -40.0, fov: float = 45.0):
        """Store the view (see the class docstring for the units)."""
        self.target = [float(v) for v in target]
        self.distance, self.yaw, self.pitch, self.fov = float(distance), float(yaw), \
            float(pitch), float(fov)


class RenderScene:
    """The cell in a DIRECT PyBullet client, posed and photographed frame by frame.

    :param cell: the cell model (default :func:`load_cell`).
    :param width: image width, px.
    :param height: image height, px.
    :param camera: the view (default :class:`Camera`).
    """

    def __init__(self, cell: Optional[CellModel] = None, width: int = 640, height: int = 360,
                 camera: Optional[Camera] = None):
        """Build the cell in a DIRECT client: the cell body only, a floor and the camera."""
        self.cell = cell if cell is not None else load_cell()
        self.width, self.height = int(width), int(height)
        self.camera = camera or Camera()
        sim_cfg = dict(load_config('simulation'), feed_interval=0.0, gui=False)
        self.sim = CellSim(self.cell, sim_cfg)
        self.pb = self.sim.client  # for its own bodies and the camera (never stepped)
        pb = self.pb
        # the cell URDF is the one body with joints; the others are the simulator's
        # collision-only bodies (the belt's rigid box, the floor plane), drawn as grey or
        # chequered stand-ins: remove them
        self.cell_body = -1  # the cell URDF's body id
        for body in [pb.getBodyUniqueId(k) for k in range(pb.getNumBodies())]:
            if pb.getNumJoints(body) == 0:
                pb.removeBody(body)
            else:
                self.cell_body = body
        floor = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[15.0, 15.0, 0.005],
                                     rgbaColor=FLOOR_RGBA)
        belt = self.cell.belt
        pb.createMultiBody(0.0, -1, floor, [(belt.x_start + belt.x_end) / 2.0,
                                            belt.centre_y, -0.005])
        self._item_shapes: Dict[Tuple[float, ...], int] = {}
        self.items: Dict[int, int] = {}  # item id -> body, the items shown now
        self._spare: Dict[Tuple[float, ...], List[int]] = {}
        self._item_colour: Dict[int, Tuple[float, ...]] = {}
        self.person: List[Tuple[PersonShape, int]] = []  # the person's shapes shown now
        self._person_spare: Dict[Tuple, List[int]] = {}
        c = self.camera
        self.view_matrix = pb.computeViewMatrixFromYawPitchRoll(
            c.target, c.distance, c.yaw, c.pitch, 0.0, 2)
        self.projection_matrix = pb.computeProjectionMatrixFOV(
            c.fov, self.width / self.height, 0.1, 50.0)

    def pose(self, q_leader: Sequence[float], q_follower: Sequence[float]) -> None:
        """Put both arms at joint positions ``(3,)`` each (clamped to the joint limits)."""
        for arm, q in zip(self.cell.arms, (q_leader, q_follower)):
            q = np.clip(np.asarray(q, dtype=float), arm.lower, arm.upper)
            self.sim.reset_arm(arm.name, q)

    def set_items(self, items: Sequence[Tuple[int, Tuple[float, ...], Sequence[float]]]
                  ) -> None:
        """Show exactly these items: ``(id, rgba, (x, y, z) centre)`` each; hide the others."""
        pb = self.pb
        seen = set()
        for item_id, rgba, pos in items:
            seen.add(item_id)
            body = self.items.get(item_id)
            if body is None:
                body = self._item_body(rgba)
                self.items[item_id] = body
                self._item_colour[item_id] = rgba
            pb.resetBasePositionAndOrientation(body, [float(v) for v in pos], [0, 0, 0, 1])
        for item_id in [i for i in self.items if i not in seen]:
            body = self.items.pop(item_id)
            pb.resetBasePositionAndOrientation(body, _HIDDEN, [0, 0, 0, 1])
            self._spare.setdefault(self._item_colour.pop(item_id), []).append(body)

    def _item_body(self, rgba: Tuple[float, ...]) -> int:
        spare = self._spare.get(rgba)
        if spare:
            return spare.pop()
        shape = self._item_shapes.get(rgba)
        if shape is None:
            half = self.cell.item_size / 2.0
            shape = self._item_shapes[rgba] = self.pb.createVisualShape(
                pybullet.GEOM_BOX, halfExtents=[half] * 3, rgbaColor=list(rgba))
        return self.pb.createMultiBody(0.0, -1, shape, list(_HIDDEN))

    def set_person(self, shapes: Sequence['PersonShape']) -> None:
        """Show exactly these shapes of a person (:func:`decode_person`); hide the others."""
        pb = self.pb
        for shape, body in self.person:
            pb.resetBasePositionAndOrientation(body, _HIDDEN, [0, 0, 0, 1])
            self._person_spare.setdefault(shape[:3], []).append(body)
        self.person = []
        for shape in shapes:
            spare = self._person_spare.get(shape[:3])
            body = spare.pop() if spare else self._person_body(*shape[:3])
            pb.resetBasePositionAndOrientation(body, list(shape.position), list(shape.quat))
            self.person.append((shape, body))

    def _person_body(self, kind: str, size: Tuple[float, ...], rgba: Tuple[float, ...]) -> int:
        pb = self.pb
        if kind == 'cylinder':
            visual = pb.createVisualShape(pybullet.GEOM_CYLINDER, radius=size[0] / 2.0,
                                          length=size[2], rgbaColor=list(rgba))
        elif kind == 'sphere':
            visual = pb.createVisualShape(pybullet.GEOM_SPHERE, radius=size[0] / 2.0,
                                          rgbaColor=list(rgba))
        else:
            visual = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[v / 2.0 for v in size],
                                          rgbaColor=list(rgba))
        return pb.createMultiBody(0.0, -1, visual, list(_HIDDEN))

    def render(self) -> np.ndarray:
        """Return the current scene as an ``(height, width, 3)`` uint8 RGB image."""
        _, _, rgba, _, _ = self.pb.getCameraImage(
            self.width, self.height, self.view_matrix, self.projection_matrix, shadow=0,
            lightDirection=[2.0, -3.0, 6.0], renderer=pybullet.ER_TINY_RENDERER)
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (self.height, self.width, 4))[
            ..., :3]

    def close(self) -> None:
        """Disconnect the client."""
        self.sim.close()

    def __enter__(self) -> 'RenderScene':
        """Return the scene itself."""
        return self

    def __exit__(self, *exc) -> None:
        """Disconnect the client."""
        self.close()


# --- the run's data --------------------------------------------------------------------------
def load_recorded(path: Union[str, Path], topics: Sequence[str]
                  ) -> Tuple[Dict[str, Tuple[np.ndarray, List[bytes]]], Reading]:
    """Return the recorded messages of ``topics`` in an MCAP file, undecoded, in one pass.

    :return: ``({topic: (log times (N,) in s, CDR bytes of each message)}, the reading
        status)``; a topic not recorded has no messages.
    """
    reading = Reading()
    found: Dict[str, Tuple[List[float], List[bytes]]] = {t: ([], []) for t in topics}
    for msg in iter_messages(path, topics, reading):
        times, data = found[msg.topic]
        times.append(msg.log_time * 1e-9)
        data.append(msg.data)
    return {t: (np.asarray(times, dtype=float), data)
            for t, (times, data) in found.items()}, reading


def load_items(path: Union[str, Path]) -> Tuple[np.ndarray, List[bytes], Reading]:
    """Return the recorded ``/conveyor/items`` of an MCAP file, undecoded.

    :return: ``(log times (N,) in s, CDR bytes of each message, the reading status)``.
    """
    found, reading = load_recorded(path, [ITEMS_TOPIC])
    return (*found[ITEMS_TOPIC], reading)


def decode_items(data: bytes) -> List[Tuple[int, Tuple[float, ...], Tuple[float, ...]]]:
    """``visualization_msgs/MarkerArray`` CDR bytes -> ``[(id, rgba, (x, y, z)), ...]``."""
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import Marker, MarkerArray
    out = []
    for m in deserialize_message(data, MarkerArray).markers:
        if m.action != Marker.ADD:
            continue
        rgba = tuple(round(float(v), 3) for v in (m.color.r, m.color.g, m.color.b, 1.0))
        p = m.pose.position
        out.append((int(m.id), rgba, (p.x, p.y, p.z)))
    return out


class PersonShape(NamedTuple):
    """One shape of a person's markers as the scene draws it (:func:`decode_person`).

    :ivar kind: ``cylinder`` (along its z), ``sphere`` or ``box``.
    :ivar size: a cylinder's diameter twice and height, a sphere's diameter three times, a
        box's edges, m (a marker's ``scale``).
    :ivar rgba: 0-1; :ivar position: ``(x, y, z)`` world, m; :ivar quat: ``(x, y, z, w)``.
    """

    kind: str
    size: Tuple[float, float, float]
    rgba: Tuple[float, float, float, float]
    position: Tuple[float, float, float]
    quat: Tuple[float, float, float, float]


def decode_person(data: bytes) -> List[PersonShape]:
    """``visualization_msgs/MarkerArray`` CDR bytes -> the person's shapes.

    The cylinders, spheres and cubes added in ``world``; other markers are left out.
    """
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import Marker, MarkerArray
    kinds = {Marker.CYLINDER: 'cylinder', Marker.SPHERE: 'sphere', Marker.CUBE: 'box'}
    out = []
    for m in deserialize_message(data, MarkerArray).markers:
        kind = kinds.get(m.type)
        if m.action != Marker.ADD or kind is None or m.header.frame_id not in ('', 'world'):
            continue
        p, o, sc, c = m.pose.position, m.pose.orientation, m.scale, m.color
        quat = (o.x, o.y, o.z, o.w) if (o.x, o.y, o.z, o.w) != (0.0,) * 4 else (0, 0, 0, 1.0)
        out.append(PersonShape(kind, tuple(round(float(v), 4) for v in (sc.x, sc.y, sc.z)),
                               tuple(round(float(v), 3) for v in (c.r, c.g, c.b, 1.0)),
                               (p.x, p.y, p.z), tuple(float(v) for v in quat)))
    return out


def frame_times(t_start: float, t_end: float, fps: float = 10.0,
                max_seconds: float = 30.0) -> np.ndarray:
    """Sim times of the frames of a time-lapse of ``[t_start, t_end]``.

    Real time (one frame per ``1 / fps`` sim s) when that fits in ``max_seconds`` of GIF,
    else ``fps * max_seconds`` frames evenly spread.

    :return: ``(n,)`` sim times, s, ``n >= 1``.
    """
    span = max(0.0, float(t_end) - float(t_start))
    n = max(1, min(math.floor(span * fps) + 1, round(fps * max_seconds)))
    return np.linspace(t_start, t_start + span, n)


def _caption(image: Image.Image, text: str, font) -> Image.Image:
    out = Image.new('RGB', (image.width, image.height + CAPTION_HEIGHT), BACKGROUND)
    out.paste(image, (0, 0))
    ImageDraw.Draw(out).text((8, image.height + 4), text, fill=(40, 40, 40), font=font)
    return out


def _palette_image(first: Image.Image, colours: Sequence[Tuple[float, ...]]) -> Image.Image:
    """Return the palette of every frame: the first frame plus swatches of the item colours."""
    swatch = 16
    strip = Image.new('RGB', (first.width, swatch * 2), BACKGROUND)
    draw = ImageDraw.Draw(strip)
    for k, rgba in enumerate(colours):
        rgb = tuple(int(round(255 * v)) for v in rgba[:3])
        shade = tuple(int(v * 0.6) for v in rgb)  # the side of a lit cube
        draw.rectangle([k * swatch, 0, (k + 1) * swatch - 1, swatch - 1], fill=rgb)
        draw.rectangle([k * swatch, swatch, (k + 1) * swatch - 1, 2 * swatch - 1], fill=shade)
    both = Image.new('RGB', (first.width, first.height + strip.height))
    both.paste(first, (0, 0))
    both.paste(strip, (0, first.height))
    return both.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)


def render_gif(run_dir: Union[str, Path], out: Optional[Union[str, Path]] = None,
               fps: float = 10.0, max_seconds: float = 30.0, width: int = 640,
               height: int = 360, camera: Optional[Camera] = None,
               progress: Optional[Callable[[str], None]] = None,
               stop: Optional[Callable[[], bool]] = None) -> Path:
    """Render a run folder as a GIF (see the module docstring).

    :param run_dir: a run folder of ``scripts/launch_cell.py`` (``timeseries.csv``; the
        optional ``summary.json``, ``events.csv``, ``run.mcap``).
    :param out: the GIF file (default ``<run_dir>/run.gif``).
    :param fps: GIF frames per second.
    :param max_seconds: longest GIF, s (longer runs become a faster time-lapse).
    :param width: image width, px (a caption strip is added below).
    :param height: image height, px.
    :param camera: the view (default :class:`Camera`).
    :param progress: called with a line of text now and then.
    :param stop: polled between frames; True ends the rendering early (the GIF keeps the
        frames rendered so far).
    :return: the GIF path.
    :raises FileNotFoundError: without ``timeseries.csv`` or with no rows in it.
    """
    run_dir = Path(run_dir)
    out = Path(out) if out is not None else run_dir / GIF_FILE
    say = progress or (lambda _text: None)
    summary: Dict = {}
    if (run_dir / report.SUMMARY).is_file():
        summary = report.read_summary(run_dir)
    ts = report.load_timeseries(run_dir)
    t = ts.get('t', np.zeros(0))
    if t.size == 0:
        raise FileNotFoundError(f'{run_dir / "timeseries.csv"} has no joint states to render')
    cell = load_cell(summary.get('profile') or None)
    names = [n for arm in cell.arms for n in arm.joint_names]
    q = np.stack([ts[n] for n in names], axis=1)
    t0 = summary.get('job_start_sim_time')
    t1 = summary.get('sim_time_end')
    t0 = float(t[0]) if t0 is None else max(float(t0), float(t[0]))
    t1 = float(t[-1]) if t1 is None else min(float(t1), float(t[-1]))
    times = frame_times(t0, max(t0, t1), fps, max_seconds)
    recorded: Dict[str, Tuple[np.ndarray, List[bytes]]] = {}
    reading = Reading()
    mcap = run_dir / MCAP_FILE
    if mcap.is_file():
        recorded, reading = load_recorded(mcap, [ITEMS_TOPIC, PERSON_TOPIC])
    item_t, item_data = recorded.get(ITEMS_TOPIC, (np.zeros(0), []))
    person_t, person_data = recorded.get(PERSON_TOPIC, (np.zeros(0), []))
    events = report.load_events(run_dir) if (run_dir / 'events.csv').is_file() else []
    ev_t = {k: np.sort([float(e['time']) for e in events if e.get('kind') == k])
            for k in ('sorted', 'missed')}
    colours = sorted({rgba for d in item_data[:: max(1, len(item_data) // 20)]
                      for _, rgba, _ in decode_items(d)}
                     | {shape.rgba for d in person_data[:: max(1, len(person_data) // 20)]
                        for shape in decode_person(d)})
    speed = (t1 - t0) / max(1e-9, len(times) / fps) if len(times) > 1 else 1.0
    items_note = (f'items from {mcap.name}' if item_data else
                  'arms only (no /conveyor/items in run.mcap)' if mcap.is_file() else
                  'arms only (record with --record to show the items)')
    if person_data:
        items_note += ', a person from /person/markers'
    cut = '' if reading.complete else f'; {mcap.name} is cut short: {reading.error}'
    say(f'[animation] {len(times)} frames of t={t0:.1f}..{t1:.1f} s at {fps:g} fps '
        f'({speed:.1f}x), {items_note}{cut}')
    try:
        font = ImageFont.load_default(size=14)
    except (TypeError, OSError):  # Pillow < 10.1 or without FreeType: the bitmap font
        font = ImageFont.load_default()
    mode = summary.get('mode', '')
    frames: List[Image.Image] = []
    palette = None
    started = time.monotonic()
    next_note = started + 5.0
    with RenderScene(cell, width, height, camera) as scene:
        for k, ft in enumerate(times):
            if stop is not None and stop():
                say(f'[animation] stopped after {k} of {len(times)} frames')
                break
            row = min(int(np.searchsorted(t, ft, side='right')) - 1, len(t) - 1)
            row = max(row, 0)
            scene.pose(q[row, :3], q[row, 3:])
            if item_data:
                j = int(np.searchsorted(item_t, ft, side='right')) - 1
                scene.set_items(decode_items(item_data[j]) if j >= 0 else [])
            if person_data:
                j = int(np.searchsorted(person_t, ft, side='right')) - 1
                scene.set_person(decode_person(person_data[j]) if j >= 0 else [])
            text = (f'scara_collab {mode}   t = {ft:6.1f} s   sorted '
                    f'{int(np.searchsorted(ev_t["sorted"], ft, side="right"))}   missed '
                    f'{int(np.searchsorted(ev_t["missed"], ft, side="right"))}   '
                    f'({speed:.1f}x)')
            image = _caption(Image.fromarray(scene.render()), text, font)
            if palette is None:
                palette = _palette_image(image, colours)
            frames.append(image.quantize(palette=palette, dither=Image.Dither.NONE))
            if time.monotonic() >= next_note:
                next_note = time.monotonic() + 5.0
                say(f'[animation] frame {k + 1}/{len(times)} '
                    f'({time.monotonic() - started:.0f} s)')
    if not frames:
        raise RuntimeError('no frame rendered')
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + '.tmp')
    frames[0].save(tmp, format='GIF', save_all=True, append_images=frames[1:],
                   duration=int(round(1000.0 / fps)), loop=0, optimize=False)
    tmp.replace(out)
    say(f'[animation] {out} ({len(frames)} frames, {out.stat().st_size / 1e6:.1f} MB) in '
        f'{time.monotonic() - started:.1f} s')
    return out


def render_after_run(run_dir: Union[str, Path], say: Callable[[str], None],
                     stop: Optional[Callable[[], bool]] = None) -> Optional[Path]:
    """Render ``run.gif`` for the launcher's ``--animation``; errors are reported, not raised."""
    try:
        return render_gif(run_dir, progress=say, stop=stop)
    except Exception as exc:  # noqa: BLE001 - the run's files are written; the GIF is extra
        say(f'[animation] not rendered: {type(exc).__name__}: {exc}')
        return None


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Render a run folder's GIF (``scripts/render_run.py``)."""
    p = argparse.ArgumentParser(prog='render_run.py', description=__doc__.split('\n')[0])
    p.add_argument('run_dir', type=Path, help='a run folder written by scripts/launch_cell.py')
    p.add_argument('--output', type=Path, default=None,
                   help=f'the GIF (default: RUN_DIR/{GIF_FILE})')
    p.add_argument('--fps', type=float, default=10.0, help='frames per second (%(default)s)')
    p.add_argument('--max-seconds', type=float, default=30.0,
                   help='longest GIF, s; longer runs play faster (%(default)s)')
    p.add_argument('--size', default='640x360', help='WIDTHxHEIGHT, px (%(default)s)')
    args = p.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split('x'))
    except ValueError:
        p.error(f'--size must look like 640x360, got {args.size!r}')
    if not (args.fps > 0 and args.max_seconds > 0 and width >= 16 and height >= 16):
        p.error('--fps and --max-seconds must be > 0 and the size at least 16x16')
    try:
        render_gif(args.run_dir, args.output, fps=args.fps, max_seconds=args.max_seconds,
                   width=width, height=height, progress=lambda s: print(s, flush=True))
    except (FileNotFoundError, RuntimeError) as exc:
        print(f'render_run: {exc}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
