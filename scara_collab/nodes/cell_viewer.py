"""``cell_viewer``: a live 3D view of the cell in the browser (viser).

Serves a viser scene (``http://localhost:<port>``, default 8080; viser ships its own web client,
so no internet is needed) built from the same cell URDF the simulator loads
(:func:`scara_collab.core.model.load_cell`): both arms posed from ``/joint_states``, the belt,
the bins (a coloured plate per item class), the items of ``/conveyor/items`` coloured by
class, the ``/<robot>/planned_path`` polylines, each arm's collision capsules
(:mod:`scara_collab.core.collision`) coloured by their distance to the other arm (green above
twice the safety margin, orange above the margin, red below, as the collision monitor's
markers) with the closest pair joined by a line, ``/collision_monitor/min_distance``, the
``/emergency_stop`` state and ``/automation_manager/stats`` in the side panel.

With a person in the cell, also: the person's capsules from ``/person/markers`` (ground truth;
markers of type cube, sphere, cylinder, line strip and line list in ``world``, drawn by their
pose, scale and colour), the returns of ``/safety_scanner/scan`` (each scanner's rays that hit
something, placed in the world by its pose and scan height from ``config/people.yaml``), and
from ``/separation_monitor/status`` the persons the monitor tracks (their columns) and each
arm's ring of ``S_p`` (its separation less its margin) around the column nearest to the arm,
at link 2's height, in the arm's path colour; each arm's speed factor in the side panel.
These parts, and their checkboxes, appear with their first message: a cell without a person
looks as it always does.

Callbacks only keep the latest message as arrays; the scene is pushed to the browser from a
wall-clock timer at ``update_rate`` (default 25 Hz), and only what changed. The viewer is an
observer: it does not take part in the bridge's lockstep, so it never paces the graph, and it
keeps drawing when sim time stands still.

Parameters (read-only): ``port`` (0 = any free port), ``host`` (default ``127.0.0.1``: this
machine only; ``0.0.0.0`` serves every interface), ``profile`` (link profile, default the
cell's), ``update_rate`` (Hz, wall), ``camera_position`` and ``camera_look_at`` (the initial
view, world frame, m).
"""
import dataclasses
import io
import math
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from nav_msgs.msg import Path
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import Bool, Float64
import trimesh
import viser
from viser.extras import ViserUrdf
from visualization_msgs.msg import Marker, MarkerArray
import yourdfpy

from scara_collab.core import collision
from scara_collab.core.config import load_config
from scara_collab.core.kinematics import base_to_world
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.palette import class_colour_255
from scara_collab.core.scan_tracking import ScanGeometry, scanners_from_config
from scara_collab.core.separation_monitor import nearest_person
from scara_collab.core.ssm import Person
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.qos import LATCHED
from scara_collab.nodes.runner import run_node

#: Planned-path colour per arm, by the arm's index in ``cell.arms``.
PATH_COLOURS = ((230, 120, 20), (20, 160, 200))
#: Capsule colours: apart (>= 2 margins), close (>= 1 margin), margin broken.
MARGIN_COLOURS = ((26, 204, 51), (242, 153, 26), (230, 26, 26))
CAPSULE_PARTS = ('link 1', 'link 2', 'quill')
#: Scan returns per scanner, in the order the scanners first report.
SCAN_COLOURS = ((220, 30, 160), (140, 60, 230))
#: The columns of the persons the separation monitor tracks.
COLUMN_COLOUR = (230, 51, 51)
RING_POINTS = 64
#: Marker types drawn, by their kind in :class:`Shape`.
MARKER_KINDS = {Marker.CUBE: 'box', Marker.SPHERE: 'sphere', Marker.CYLINDER: 'cylinder',
                Marker.LINE_STRIP: 'lines', Marker.LINE_LIST: 'lines'}


# --- presentation helpers (numpy, no rclpy) ------------------------------------------------
def class_colour(cls: str, classes: Sequence[str]) -> Tuple[int, int, int]:
    """RGB colour (0-255) of an item class (:mod:`scara_collab.core.palette`)."""
    return class_colour_255(cls, classes)


def margin_colour(distance: float, margin: float) -> Tuple[int, int, int]:
    """RGB colour of a capsule ``distance`` m from the other arm, for a safety ``margin`` m."""
    if distance < margin:
        return MARGIN_COLOURS[2]
    if distance < 2.0 * margin:
        return MARGIN_COLOURS[1]
    return MARGIN_COLOURS[0]


def segment_pose(start: np.ndarray, end: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Pose that puts a mesh built along z around the origin onto the segment ``start-end``.

    :param start: (3,) segment start, m.
    :param end: (3,) segment end, m.
    :return: ``(wxyz, position)``: the unit quaternion turning +z onto the segment direction,
        and the segment midpoint.
    """
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    d = end - start
    n = float(np.linalg.norm(d))
    u = d / n if n > 0 else np.array([0.0, 0.0, 1.0])
    # Half-way quaternion between +z and u: (1 + z.u, z x u), normalised; antiparallel -> x.
    q = np.array([1.0 + u[2], -u[1], u[0], 0.0])
    norm = float(np.linalg.norm(q))
    wxyz = q / norm if norm > 1e-9 else np.array([0.0, 1.0, 0.0, 0.0])
    return wxyz, (start + end) / 2.0


def urdf_subtree(robot: yourdfpy.Robot, roots: Sequence[str]) -> List[str]:
    """Links of ``robot`` under (and including) the links ``roots``, in tree order."""
    children: Dict[str, List[str]] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j.child)
    out, todo = [], list(roots)
    while todo:
        link = todo.pop(0)
        out.append(link)
        todo.extend(children.get(link, []))
    return out


def urdf_part(cell_urdf: yourdfpy.URDF, links: Sequence[str], name: str) -> yourdfpy.URDF:
    """Return a URDF of some of the cell's links (and the joints between them), meshes loaded.

    :param cell_urdf: the parsed cell URDF.
    :param links: the links to keep; must include the root (``world``).
    :param name: the new robot name.
    """
    keep = set(links)
    robot = cell_urdf.robot
    part = yourdfpy.Robot(name=name, links=[lk for lk in robot.links if lk.name in keep],
                          joints=[j for j in robot.joints if j.child in keep],
                          materials=list(robot.materials))
    return yourdfpy.URDF(robot=part, build_scene_graph=True, load_meshes=True)


def stats_markdown(status: Optional[Tuple[str, Dict[str, str]]]) -> str:
    """Markdown of the automation stats (``(message, key-values)``), or a waiting note."""
    if status is None:
        return '*no `/automation_manager/stats` yet*'
    message, values = status
    rows = '\n'.join(f'| {k} | {v} |' for k, v in values.items())
    return f'**{message}**\n\n| | |\n|---|---|\n{rows}'


class Shape(NamedTuple):
    """A marker as the scene draws it (:func:`marker_shape`), in the world frame.

    :ivar kind: ``box``, ``sphere``, ``cylinder`` (along its z) or ``lines``.
    :ivar position: ``(x, y, z)``, m; :ivar wxyz: its rotation, a unit quaternion.
    :ivar size: edges of a box, diameters in x and y and the height in z of a cylinder, the
        diameters of a sphere, m; of lines, ``(width, 0, 0)``.
    :ivar colour: RGB, 0-255; :ivar opacity: 0-1.
    :ivar segments: lines only: ``(N, 2, 3)`` in the shape's frame, m.
    """

    kind: str
    position: Tuple[float, float, float]
    wxyz: Tuple[float, float, float, float]
    size: Tuple[float, float, float]
    colour: Tuple[int, int, int]
    opacity: float
    segments: Optional[np.ndarray] = None


def marker_shape(marker: Marker) -> Optional[Shape]:
    """Return what the scene draws of a ``visualization_msgs/Marker`` (an ADD), in its frame.

    As RViz draws it: a cube, sphere or cylinder by its pose and scale (``scale.x`` and
    ``scale.y`` the diameters, ``scale.z`` the height), lines through ``points`` in the pose's
    frame, ``scale.x`` wide; a zero quaternion is no rotation.

    :return: the :class:`Shape`, or None for another type, non-finite numbers or lines of
        fewer than two points.
    """
    kind = MARKER_KINDS.get(marker.type)
    if kind is None:
        return None
    p, o, sc, c = marker.pose.position, marker.pose.orientation, marker.scale, marker.color
    quat = np.array([o.w, o.x, o.y, o.z], dtype=float)
    norm = float(np.linalg.norm(quat))
    wxyz = quat / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0, 0.0])
    size = (sc.x, sc.y, sc.z) if kind != 'lines' else (sc.x, 0.0, 0.0)
    segments = None
    if kind == 'lines':
        pts = np.array([[q.x, q.y, q.z] for q in marker.points], dtype=float).reshape(-1, 3)
        if marker.type == Marker.LINE_STRIP:
            segments = np.stack([pts[:-1], pts[1:]], axis=1)
        else:
            segments = pts[:len(pts) // 2 * 2].reshape(-1, 2, 3)
        if len(segments) == 0 or not np.all(np.isfinite(segments)):
            return None
    numbers = np.array([p.x, p.y, p.z, *size, c.r, c.g, c.b, c.a], dtype=float)
    if not (np.all(np.isfinite(numbers)) and np.all(np.isfinite(quat))):
        return None
    rgb = tuple(int(round(255.0 * min(max(v, 0.0), 1.0))) for v in (c.r, c.g, c.b))
    return Shape(kind, (float(p.x), float(p.y), float(p.z)), tuple(float(v) for v in wxyz),
                 tuple(float(v) for v in size), rgb, min(max(float(c.a), 0.0), 1.0), segments)


def scan_points(geometry: ScanGeometry, ranges: np.ndarray, angle_min: float,
                angle_increment: float, range_min: float, range_max: float) -> np.ndarray:
    """Return the world points of a scan's returns: the rays that hit something.

    :param geometry: the scanner (its pose on the floor and its scan height).
    :param ranges: ``(N,)`` m, ``inf`` for no return; NaN and out-of-range values are no hit.
    :param angle_min: the first ray's angle in the scanner's frame, rad (the message's).
    :param angle_increment: between rays, rad (the message's).
    :param range_min: :param range_max: the valid ranges, m (the message's).
    :return: ``(M, 3)`` world, m, at the scan height.
    """
    ranges = np.asarray(ranges, dtype=float)
    rays = dataclasses.replace(geometry, angle_min=float(angle_min),
                               angle_increment=float(angle_increment), count=len(ranges))
    with np.errstate(invalid='ignore'):
        hit = np.isfinite(ranges) & (ranges >= range_min) & (ranges <= range_max)
    xy = rays.points(ranges, hit)
    return np.column_stack([xy, np.full(len(xy), geometry.height)])


def ring_segments(centre: Sequence[float], radius: float, z: float,
                  count: int = RING_POINTS) -> np.ndarray:
    """Return a horizontal circle as ``(count, 2, 3)`` line segments, world, m."""
    a = np.linspace(0.0, 2.0 * math.pi, count + 1)
    pts = np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a),
                           np.full(len(a), float(z))])
    return np.stack([pts[:-1], pts[1:]], axis=1)


def separation_markdown(status: proto.SeparationStatus) -> str:
    """Markdown of the separation monitor's decision: each arm's factor, ``S`` and ``S_p``."""
    count = len(status.persons)
    head = f'**Separation monitor**: {count} person{"" if count == 1 else "s"} tracked'
    if status.fault:
        head += f'\n\n**every arm stopped**: {status.fault}'
    rows, causes = [], []
    for robot, scale in status.scale.items():
        sep = status.separation.get(robot, math.inf)
        s_p = sep - status.margin.get(robot, math.inf)
        speed = 'stop' if status.stop.get(robot) else f'x {scale:.2f}'
        metres = (f'{sep:.2f} | {s_p:.2f}' if math.isfinite(sep) and math.isfinite(s_p)
                  else '- | -')
        rows.append(f'| {robot} | {speed} | {metres} |')
        if status.cause.get(robot):
            causes.append(f'- *{status.cause[robot]}*')
    table = '| arm | speed | S m | S_p m |\n|---|---|---|---|\n' + '\n'.join(rows)
    return '\n\n'.join([head, table] + (['\n'.join(causes)] if causes else []))


class ViserScene:
    """The viser scene of the cell; knows nothing of ROS (arrays in, scene out).

    :ivar server: the viser server.
    :ivar urdfs: ``{robot: yourdfpy.URDF}`` each arm's part of the cell URDF, as last posed.
    :ivar root: ``{part: frame handle}`` of the parts :meth:`set_visible` shows and hides.
    :ivar capsules: ``{robot: [3 mesh handles]}`` (link 1, link 2, quill).
    :ivar items: ``{item id: box handle}``.
    :ivar paths: ``{robot: line segments handle}``.
    :ivar person: ``{(marker ns, id): (handle, Shape)}`` the person's markers drawn.
    :ivar scans: ``{scanner: point cloud handle}`` each scanner's returns.
    :ivar columns: ``{track id: cylinder handle}`` the persons the separation monitor tracks.
    :ivar rings: ``{robot: line segments handle}`` each arm's ``S_p`` ring.
    """

    def __init__(self, server: viser.ViserServer, cell: CellModel):
        """Add the grid, the fixed cell and one posable URDF, capsules and path per arm."""
        self.server, self.cell = server, cell
        scene = server.scene
        scene.set_up_direction('+z')
        scene.add_grid('/ground', width=12.0, height=10.0, position=(2.0, 0.0, 0.0),
                       cell_size=0.5, section_size=1.0)
        xml = yourdfpy.URDF.load(io.StringIO(cell.urdf), build_scene_graph=False,
                                 load_meshes=False)
        arm_links = {a.name: urdf_subtree(xml.robot, [f'{a.name}_base_link'])
                     for a in cell.arms}
        taken = {lk for links in arm_links.values() for lk in links}
        env = [lk.name for lk in xml.robot.links if lk.name not in taken]
        self.root = {'cell': scene.add_frame('/cell', show_axes=False)}
        # ViserUrdf places its joint frames in update_cfg: once for the fixed belt and bins.
        ViserUrdf(server, urdf_part(xml, env, 'cell'), root_node_name='/cell').update_cfg(
            np.zeros(0))
        self.urdfs: Dict[str, yourdfpy.URDF] = {}
        self._views: Dict[str, ViserUrdf] = {}
        self.root['arms'] = scene.add_frame('/arms', show_axes=False, visible=False)
        self.posed = False  # the arms are hidden until the first joint state
        for a in cell.arms:
            scene.add_frame(f'/arms/{a.name}', show_axes=False)
            self.urdfs[a.name] = urdf_part(xml, ['world'] + arm_links[a.name], a.name)
            self._views[a.name] = ViserUrdf(server, self.urdfs[a.name],
                                            root_node_name=f'/arms/{a.name}')
        self._add_bin_plates()
        self.root['capsules'] = scene.add_frame('/capsules', show_axes=False)
        self.capsules: Dict[str, list] = {}
        for a in cell.arms:
            lengths = (a.l1, a.l2, a.quill_length)
            radii = (a.link_radius, a.link_radius, a.quill_radius)
            meshes = [trimesh.creation.capsule(height=h, radius=r, count=[16, 16])
                      for h, r in zip(lengths, radii)]
            self.capsules[a.name] = [  # hidden until the first joint state
                scene.add_mesh_simple(f'/capsules/{a.name}/{k}', m.vertices, m.faces,
                                      color=MARGIN_COLOURS[0], opacity=0.35, visible=False)
                for k, m in enumerate(meshes)]
        self.gap = scene.add_line_segments('/capsules/gap', np.zeros((1, 2, 3)),
                                           MARGIN_COLOURS[0], thickness=0.015, visible=False)
        self.gap_label = scene.add_label('/capsules/gap_label', '', visible=False)
        self.root['items'] = scene.add_frame('/items', show_axes=False)
        self.items: Dict[int, object] = {}
        self.root['paths'] = scene.add_frame('/paths', show_axes=False)
        self.paths: Dict[str, object] = {}
        belt = cell.belt
        self.estop_label = scene.add_label(
            '/estop', 'EMERGENCY STOP', position=((belt.x_start + belt.x_end) / 2,
                                                  belt.centre_y, 1.6),
            font_screen_scale=2.0, visible=False)
        self._q: Dict[str, np.ndarray] = {}
        self.distance: Optional[float] = None  # arm-to-arm, from the drawn joint states
        # a person in the cell: the parts appear with their first message
        self.person: Dict[Tuple[str, int], Tuple[object, Shape]] = {}
        self.scans: Dict[str, object] = {}
        self.columns: Dict[int, object] = {}
        self.rings: Dict[str, object] = {}
        self._gui()

    def _add_bin_plates(self) -> None:
        size = self.cell.config['bins']['size']
        self.server.scene.add_frame('/cell/bin_plates', show_axes=False)
        for (robot, cls), centre in self.cell.bins.items():
            self.server.scene.add_box(
                f'/cell/bin_plates/{robot}_{cls}', dimensions=(size[0] * 0.8, size[1] * 0.8,
                                                               0.01),
                color=class_colour(cls, self.cell.item_classes),
                position=(float(centre[0]), float(centre[1]), float(centre[2]) + 0.03))

    def _gui(self) -> None:
        gui = self.server.gui
        self.status_md = gui.add_markdown('*waiting for `/joint_states`*')
        with gui.add_folder('Automation'):
            self.stats_md = gui.add_markdown(stats_markdown(None))
        self._show_folder = gui.add_folder('Show')
        self.show = {}
        for name in ('arms', 'capsules', 'paths', 'items', 'cell'):
            self._add_checkbox(name)

    def _add_checkbox(self, name: str) -> None:
        with self._show_folder:
            box = self.show[name] = self.server.gui.add_checkbox(name, True)
        box.on_update(lambda _event: self.set_visible(name, box.value))

    def _part(self, name: str) -> str:
        """Return the root of the part ``name`` (``person``, ``scan``, ``separation``).

        Its frame and its checkbox are made on first use.
        """
        if name not in self.root:
            self.root[name] = self.server.scene.add_frame(f'/{name}', show_axes=False)
            self._add_checkbox(name)
        return f'/{name}'

    def set_visible(self, part: str, visible: bool) -> None:
        """Show or hide a part.

        The parts: ``arms``, ``capsules``, ``paths``, ``items``, ``cell``; and ``person``,
        ``scan``, ``separation`` once they have been drawn.
        """
        self.root[part].visible = bool(visible) and (part != 'arms' or self.posed)
        if self.show[part].value != bool(visible):
            self.show[part].value = bool(visible)

    def set_camera(self, position: Sequence[float], look_at: Sequence[float],
                   fov: float = math.radians(50.0)) -> None:
        """Set the view of new browser tabs (and their "Reset View"); ``fov`` vertical, rad."""
        cam = self.server.initial_camera
        cam.position = tuple(float(v) for v in position)
        cam.look_at = tuple(float(v) for v in look_at)
        cam.up = (0.0, 0.0, 1.0)
        cam.fov = float(fov)

    # --- updates ---------------------------------------------------------------------------
    def set_arms(self, q: Dict[str, np.ndarray]) -> bool:
        """Pose the arms (``{robot: (3,) joints}``) and their capsules; False if unchanged."""
        if q.keys() != self.urdfs.keys():
            return False
        if self._q and all(np.allclose(q[n], self._q[n], atol=1e-6, rtol=0) for n in q):
            return False
        for name, view in self._views.items():
            view.update_cfg(np.asarray(q[name], dtype=float))
        self._q = {n: np.array(v, dtype=float) for n, v in q.items()}
        if not self.posed:
            self.posed = True
            self.set_visible('arms', self.show['arms'].value)
        a, b = self.cell.arms
        pairs, d, p, pq = collision.closest_points(a, self._q[a.name], b, self._q[b.name])
        per_capsule = np.stack([pairs.min(axis=1), pairs.min(axis=0)])  # row 0 a, row 1 b
        margin = self.cell.safety_margin
        for row, arm in enumerate(self.cell.arms):
            starts, ends, _ = collision.arm_capsules(arm, self._q[arm.name])
            for k, handle in enumerate(self.capsules[arm.name]):
                handle.wxyz, handle.position = segment_pose(starts[k], ends[k])
                handle.color = margin_colour(float(per_capsule[row, k]), margin)
                handle.visible = True
        colour = margin_colour(d, margin)
        self.gap.points = np.array([[p, pq]], dtype=np.float32)
        self.gap.colors = np.array([[colour, colour]], dtype=np.uint8)
        self.gap.visible = True
        self.gap_label.text = f'{d:.3f} m'
        self.gap_label.position = tuple((p + pq) / 2.0 + np.array([0.0, 0.0, 0.15]))
        self.gap_label.visible = True
        self.distance = d
        return True

    def set_items(self, items: Dict[int, Tuple[str, np.ndarray]]) -> None:
        """Show exactly ``items`` (``{id: (class, (3,) position)}``)."""
        for k in [k for k in self.items if k not in items]:
            self.items.pop(k).remove()
        size = self.cell.item_size
        for k, (cls, xyz) in items.items():
            pos = tuple(float(v) for v in xyz)
            if k in self.items:
                self.items[k].position = pos
            else:
                self.items[k] = self.server.scene.add_box(
                    f'/items/{k}', dimensions=(size, size, size),
                    color=class_colour(cls, self.cell.item_classes), position=pos)

    def set_path(self, robot: str, points: np.ndarray) -> None:
        """Draw the planned path of ``robot`` ((N, 3) world points; N < 2 clears it)."""
        old = self.paths.pop(robot, None)
        if old is not None:
            old.remove()
        if len(points) < 2:
            return
        names = [a.name for a in self.cell.arms]
        colour = PATH_COLOURS[names.index(robot) % len(PATH_COLOURS)]
        segments = np.stack([points[:-1], points[1:]], axis=1)
        self.paths[robot] = self.server.scene.add_line_segments(
            f'/paths/{robot}', segments, colour, thickness=0.02)

    def set_person(self, shapes: Dict[Tuple[str, int], Shape]) -> None:
        """Show exactly the person's markers ``shapes`` (``{(ns, id): Shape}``, world)."""
        root = self._part('person')
        for key in [k for k in self.person if k not in shapes]:
            self.person.pop(key)[0].remove()
        for key, shape in shapes.items():
            handle, old = self.person.get(key, (None, None))
            if old is not None and old.kind == shape.kind:
                _update_shape(handle, old, shape)
            else:
                if handle is not None:
                    handle.remove()
                ns = key[0] or '_'  # a scene name has no empty part
                handle = _add_shape(self.server.scene, f'{root}/{ns}/{key[1]}', shape)
            self.person[key] = (handle, shape)

    def set_scan(self, scanner: str, points: np.ndarray) -> None:
        """Show the returns ``(M, 3)`` (world, m) of ``scanner``'s latest scan."""
        points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        handle = self.scans.get(scanner)
        if handle is None:
            root = self._part('scan')
            colour = SCAN_COLOURS[len(self.scans) % len(SCAN_COLOURS)]
            handle = self.scans[scanner] = self.server.scene.add_point_cloud(
                f'{root}/{scanner}', points, colour, point_size=0.05, precision='float32')
        else:
            handle.points = points

    def set_separation(self, status: proto.SeparationStatus, column_height: float) -> None:
        """Draw the tracked persons' columns and each arm's ``S_p`` ring around the nearest.

        ``S_p`` is the arm's separation less its margin; the ring's radius is the column's
        radius plus ``S_p`` (``S`` is measured from the column's surface), at link 2's
        height. An arm without a person, or not yet posed, has no ring.

        :param status: the separation monitor's decision.
        :param column_height: m, the columns' height (``monitor.column_height``).
        """
        root = self._part('separation')
        persons = [Person(np.array([p.x, p.y]), np.array([p.vx, p.vy]), p.radius,
                          column_height, p.id) for p in status.persons]
        for k in [k for k in self.columns if k not in {p.id for p in persons}]:
            self.columns.pop(k).remove()
        for p in persons:
            handle = self.columns.get(p.id)
            if handle is None:
                handle = self.columns[p.id] = self.server.scene.add_cylinder(
                    f'{root}/columns/{p.id}', radius=1.0, height=column_height,
                    color=COLUMN_COLOUR, opacity=0.25)
            handle.position = (float(p.position[0]), float(p.position[1]), column_height / 2)
            handle.scale = (p.radius, p.radius, 1.0)
        for k, arm in enumerate(self.cell.arms):
            sep = status.separation.get(arm.name, math.inf)
            s_p = sep - status.margin.get(arm.name, math.inf)
            q = self._q.get(arm.name)
            near = (nearest_person(arm, q, persons) if q is not None and math.isfinite(s_p)
                    and s_p > 0.0 else None)
            ring = self.rings.get(arm.name)
            if near is None:
                if ring is not None:
                    ring.visible = False
                continue
            z = float(collision.arm_capsules(arm, q)[0][1, 2])  # link 2's start: the elbow
            segments = ring_segments(near.position, near.radius + s_p, z)
            if ring is None:
                colour = PATH_COLOURS[k % len(PATH_COLOURS)]
                self.rings[arm.name] = self.server.scene.add_line_segments(
                    f'{root}/rings/{arm.name}', segments, colour, thickness=0.03)
            else:
                ring.points = segments.astype(np.float32)
                ring.visible = True

    def set_status(self, sim_time: float, estop: Optional[bool], monitor: Optional[float],
                   separation: Optional[proto.SeparationStatus] = None) -> None:
        """Side panel: sim time, e-stop, arm-to-arm distance (ours and the monitor's).

        With a ``separation`` status, each arm's speed factor, ``S`` and ``S_p`` below.
        """
        stop = ('**E-stop: ACTIVE** (both arms hold)' if estop else
                'E-stop: clear' if estop is not None else 'E-stop: *unknown*')
        dist = 'n/a' if self.distance is None else f'{self.distance:.3f} m'
        mon = 'n/a' if monitor is None else f'{monitor:.3f} m'
        text = (f'sim t = {sim_time:.2f} s\n\n{stop}\n\narm distance {dist} (monitor {mon}); '
                f'margin {self.cell.safety_margin:g} m')
        if separation is not None:
            text += '\n\n' + separation_markdown(separation)
        if self.status_md.content != text:
            self.status_md.content = text
        if self.estop_label.visible != bool(estop):
            self.estop_label.visible = bool(estop)

    def set_stats(self, status: Optional[Tuple[str, Dict[str, str]]]) -> None:
        """Automation stats panel (``(message, key-values)``)."""
        self.stats_md.content = stats_markdown(status)


def _add_shape(scene, name: str, shape: Shape):
    """Add ``shape`` to the viser ``scene`` as ``name``; return its handle."""
    opacity = shape.opacity if shape.opacity < 1.0 else None
    pose = dict(wxyz=shape.wxyz, position=shape.position)
    if shape.kind == 'box':
        return scene.add_box(name, dimensions=shape.size, color=shape.colour, opacity=opacity,
                             **pose)
    if shape.kind == 'sphere':
        return scene.add_icosphere(name, radius=0.5, color=shape.colour, subdivisions=2,
                                   scale=shape.size, opacity=opacity, **pose)
    if shape.kind == 'cylinder':
        return scene.add_cylinder(name, radius=0.5, height=1.0, color=shape.colour,
                                  scale=shape.size, opacity=opacity, **pose)
    return scene.add_line_segments(name, shape.segments, shape.colour,
                                   thickness=max(shape.size[0], 1e-3), **pose)


def _update_shape(handle, old: Shape, new: Shape) -> None:
    """Change a handle drawn as ``old`` (of ``new``'s kind) to ``new``, what differs only."""
    if new.position != old.position:
        handle.position = new.position
    if new.wxyz != old.wxyz:
        handle.wxyz = new.wxyz
    if new.colour != old.colour:
        handle.color = new.colour
    if new.opacity != old.opacity and new.kind != 'lines':  # lines are opaque
        handle.opacity = new.opacity if new.opacity < 1.0 else None
    if new.kind == 'lines':
        if not np.array_equal(new.segments, old.segments):
            handle.points = new.segments.astype(np.float32)
        if new.size != old.size:
            handle.thickness = max(new.size[0], 1e-3)
    elif new.size != old.size:
        if new.kind == 'box':
            handle.dimensions = new.size
        else:
            handle.scale = new.size


class CellViewer(Node):
    """Serve the live 3D view; ``scene`` is the :class:`ViserScene`, ``server`` its server."""

    def __init__(self, **kwargs):
        """Declare and check the parameters, start the viser server and subscribe.

        :param kwargs: passed to :class:`rclpy.node.Node` (``context``, ``parameter_overrides``).
        :raises ValueError: a port, update rate or camera vector out of range.
        """
        super().__init__('cell_viewer', **kwargs)
        ro = ParameterDescriptor(read_only=True)
        self.declare_parameter('port', 8080, ro)
        self.declare_parameter('host', '127.0.0.1', ro)
        self.declare_parameter('profile', '', ro)
        self.declare_parameter('update_rate', 25.0, ro)
        self.declare_parameter('camera_position', [0.2, -5.2, 5.6], ro)
        self.declare_parameter('camera_look_at', [2.9, 0.3, 0.3], ro)
        port = int(self.get_parameter('port').value)
        rate = float(self.get_parameter('update_rate').value)
        camera = [np.asarray(self.get_parameter(k).value, dtype=float)
                  for k in ('camera_position', 'camera_look_at')]
        if not 0 <= port <= 65535:
            raise ValueError(f'cell_viewer: port must be in 0..65535 (0 = any), got {port}')
        if not (math.isfinite(rate) and 0.0 < rate <= 60.0):
            raise ValueError(f'cell_viewer: update_rate must be in (0, 60] Hz, got {rate}')
        for name, v in zip(('camera_position', 'camera_look_at'), camera):
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ValueError(f'cell_viewer: {name} must be 3 finite numbers, got {v}')
        self.cell = load_cell(self.get_parameter('profile').value or None)
        people = load_config('people')
        self.scanners = {g.name: g for g in scanners_from_config(people)}
        self.column_height = float(people['monitor']['column_height'])
        self.scene: Optional[ViserScene] = None
        self.q: Dict[str, np.ndarray] = {}
        self.items: Optional[Dict[int, Tuple[str, np.ndarray]]] = None
        self.paths: Dict[str, np.ndarray] = {}
        self.estop: Optional[bool] = None
        self.monitor: Optional[float] = None
        self.stats: Optional[Tuple[str, Dict[str, str]]] = None
        self.person: Optional[Dict[Tuple[str, int], Shape]] = None  # the markers shown
        self.scans: Dict[str, tuple] = {}  # scanner: (ranges, angle_min, increment, min, max)
        self.separation: Optional[proto.SeparationStatus] = None
        self.frames = 0  # scene updates that moved the arms
        self._dirty = set()

        self.create_subscription(JointState, 'joint_states', self._on_state,
                                 QoSProfile(depth=1))
        self.create_subscription(MarkerArray, 'conveyor/items', self._on_items, 10)
        for a in self.cell.arms:
            self.create_subscription(Path, f'{a.name}/planned_path',
                                     lambda m, n=a.name: self._on_path(n, m), 10)
        self.create_subscription(Float64, 'collision_monitor/min_distance',
                                 self._on_distance, 10)
        self.create_subscription(Bool, 'emergency_stop', self._on_estop, LATCHED)
        self.create_subscription(DiagnosticStatus, 'automation_manager/stats', self._on_stats,
                                 10)
        self.create_subscription(MarkerArray, 'person/markers', self._on_person, 10)
        self.create_subscription(LaserScan, 'safety_scanner/scan', self._on_scan, 10)
        self.create_subscription(DiagnosticStatus, 'separation_monitor/status',
                                 self._on_separation, 10)
        self.create_timer(1.0 / rate, self._draw,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        # The server last: once its page answers, the node is on the graph (the launcher's
        # readiness), and a failure here leaves no server thread behind.
        self.server = viser.ViserServer(host=str(self.get_parameter('host').value), port=port,
                                        label='scara_collab cell', verbose=False)
        try:
            self.scene = ViserScene(self.server, self.cell)
            self.scene.set_camera(*camera)
        except BaseException:
            self.server.stop()
            raise
        self.port = self.server.get_port()
        self.get_logger().info(f'live 3D view of the cell on http://localhost:{self.port} '
                               f'(host {self.server.get_host()}, {rate:g} Hz)')

    # --- inputs ----------------------------------------------------------------------------
    def _on_state(self, msg: JointState) -> None:
        try:
            q = {a.name: conv.joint_state_arrays(msg, a.joint_names)[0] for a in self.cell.arms}
        except conv.MessageError as exc:
            self.get_logger().warning(f'ignoring joint_states: {exc}', throttle_duration_sec=5.0)
            return
        if all(np.all(np.isfinite(v)) for v in q.values()):
            self.q = q
            self._dirty.add('arms')

    def _on_items(self, msg: MarkerArray) -> None:
        self.items = {k: (cls, xyz) for k, (cls, xyz, _) in conv.item_positions(msg).items()}
        self._dirty.add('items')

    def _on_path(self, robot: str, msg: Path) -> None:
        points = conv.path_points(msg)
        frame = msg.header.frame_id
        if frame == f'{robot}_base':
            points = base_to_world(self.cell.arm(robot), points)
        elif frame not in ('', 'world'):
            self.get_logger().warning(f'{robot}/planned_path in unknown frame {frame!r}; '
                                      'not drawn', throttle_duration_sec=5.0)
            return
        if not np.all(np.isfinite(points)):
            self.get_logger().warning(f'{robot}/planned_path has non-finite points; not drawn',
                                      throttle_duration_sec=5.0)
            return
        self.paths[robot] = points
        self._dirty.add(f'path:{robot}')

    def _on_distance(self, msg: Float64) -> None:
        self.monitor = float(msg.data)

    def _on_estop(self, msg: Bool) -> None:
        self.estop = bool(msg.data)

    def _on_stats(self, msg: DiagnosticStatus) -> None:
        try:
            st = proto.JobStats.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring job stats: {exc}', throttle_duration_sec=5.0)
            return
        self.stats = (st.text(), {**st.counts, 'items/min': st.items_per_minute,
                                  **{f'sorted by {r}': n for r, n in st.sorted_by.items()},
                                  'give-ups': st.give_ups, 'retries': st.retries,
                                  'running': st.running})
        self._dirty.add('stats')

    def _on_person(self, msg: MarkerArray) -> None:
        shapes = dict(self.person or {})
        for m in msg.markers:
            key = (m.ns, int(m.id))
            if m.action == Marker.DELETEALL:
                shapes.clear()
            elif m.action == Marker.DELETE:
                shapes.pop(key, None)
            elif m.header.frame_id not in ('', 'world'):
                self.get_logger().warning(f'person/markers: {m.ns}/{m.id} in frame '
                                          f'{m.header.frame_id!r}, not world; not drawn',
                                          throttle_duration_sec=5.0)
            else:
                shape = marker_shape(m)
                if shape is None:
                    self.get_logger().warning(
                        f'person/markers: {m.ns}/{m.id} (type {m.type}) is not a finite cube, '
                        'sphere, cylinder or line; not drawn', throttle_duration_sec=5.0)
                    shapes.pop(key, None)
                else:
                    shapes[key] = shape
        self.person = shapes
        self._dirty.add('person')

    def _on_scan(self, msg: LaserScan) -> None:
        frame = msg.header.frame_id
        if frame not in self.scanners:
            self.get_logger().warning(f'safety_scanner/scan from {frame!r}, not a scanner of '
                                      f'config/people.yaml ({", ".join(self.scanners)}); '
                                      'not drawn', throttle_duration_sec=5.0)
            return
        self.scans[frame] = (np.asarray(msg.ranges, dtype=float), msg.angle_min,
                             msg.angle_increment, msg.range_min, msg.range_max)
        self._dirty.add(f'scan:{frame}')

    def _on_separation(self, msg: DiagnosticStatus) -> None:
        try:
            self.separation = proto.SeparationStatus.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring a separation status: {exc}',
                                      throttle_duration_sec=5.0)
            return
        self._dirty.add('separation')

    # --- output ----------------------------------------------------------------------------
    def _draw(self) -> None:
        if self.scene is None:  # still being built
            return
        dirty, self._dirty = self._dirty, set()
        if 'arms' in dirty and self.scene.set_arms(self.q):
            self.frames += 1
        if 'items' in dirty and self.items is not None:
            self.scene.set_items(self.items)
        for robot, points in self.paths.items():
            if f'path:{robot}' in dirty:
                self.scene.set_path(robot, points)
        if 'stats' in dirty:
            self.scene.set_stats(self.stats)
        if 'person' in dirty:
            self.scene.set_person(self.person)
        for frame, scan in self.scans.items():
            if f'scan:{frame}' in dirty:
                self.scene.set_scan(frame, scan_points(self.scanners[frame], *scan))
        if self.separation is not None and dirty & {'separation', 'arms'}:
            self.scene.set_separation(self.separation, self.column_height)
        sim = self.get_clock().now().nanoseconds * 1e-9
        self.scene.set_status(sim, self.estop, self.monitor, self.separation)

    def destroy_node(self):
        """Stop the viser server, then destroy the node."""
        self.server.stop()
        return super().destroy_node()


def main(args=None) -> None:
    """Run the live 3D view: ``ros2 run scara_collab cell_viewer``."""
    run_node(CellViewer, args)


if __name__ == '__main__':
    main()
