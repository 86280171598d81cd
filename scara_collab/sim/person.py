"""The simulated person: a body of capsules in the cell's PyBullet world, moved along a path.

The body (:class:`BodyModel`, ``config/people.yaml``): two legs from the hips to the feet, a
torso that leans forward, a head, and two arms from the shoulders: the left one hangs, the
right one swings from hanging to reaching forward and down (``reach_pitch`` below horizontal;
``reach`` = 0.85 m from the shoulder to the fingertips, ISO 13857). While walking the feet
swing fore and aft, half a step out of phase, so a floor scanner sees two legs that move. The
pose comes from the keyframes of :class:`~scara_collab.sim.person_scenarios.PersonPath`
(:func:`body_capsules`, plain numpy, also for N times at once).

:class:`PersonSim` puts that body into a PyBullet world it is given (the
:class:`~scara_collab.sim.cell_sim.CellSim`'s client, no client of its own): one static
capsule body per segment, moved with ``resetBasePositionAndOrientation`` by
:meth:`PersonSim.update` (at the item rate, say), parked far below the floor while the person
is away. The scanner's rays hit it; it does not push the arms (its collision with the cell's
body is filtered out), and its contact with the arms is *detected*
(:meth:`PersonSim.contacts`, PyBullet's closest points against the arms' links). Its ground
truth (:meth:`PersonSim.poses`, one pose per capsule centre; :meth:`PersonSim.capsules`) is for
recording, viewers and tests only: no decision reads it.
"""
from dataclasses import dataclass
import math
from typing import List, NamedTuple, Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike
import pybullet

from scara_collab.core import collision
from scara_collab.core.model import ArmModel
from scara_collab.sim.person_scenarios import COLUMNS, PersonPath

#: the capsules, in the order of every array of this module
SEGMENTS = ('left_leg', 'right_leg', 'torso', 'head', 'left_arm', 'right_arm')
#: where an absent person is parked: far below the floor, out of every ray's way, m
PARKED = (0.0, 0.0, -50.0)
_IX = {c: i for i, c in enumerate(COLUMNS)}


@dataclass(frozen=True)
class BodyModel:
    """The body's sizes, m (``config/people.yaml``, ``person.body``)."""

    leg_radius: float
    hip_height: float
    stance: float
    step_amplitude: float
    step_length: float
    torso_radius: float
    torso_length: float
    shoulder_offset: float
    head_radius: float
    neck: float
    arm_radius: float
    reach: float
    reach_pitch: float

    @staticmethod
    def from_config(cfg: dict) -> 'BodyModel':
        """Build it from the validated ``people`` config."""
        body = cfg['person']['body']
        return BodyModel(reach_pitch=float(cfg['person']['work']['reach_pitch']),
                         **{k: float(v) for k, v in body.items()})

    @property
    def radii(self) -> np.ndarray:
        """The capsules' radii, ``(6,)`` in :data:`SEGMENTS` order."""
        return np.array([self.leg_radius, self.leg_radius, self.torso_radius, self.head_radius,
                         self.arm_radius, self.arm_radius])

    @property
    def lengths(self) -> np.ndarray:
        """The capsules' axis lengths, ``(6,)`` (the head is a sphere)."""
        leg = self.hip_height - self.leg_radius
        arm = self.reach - self.arm_radius
        return np.array([leg, leg, self.torso_length, 0.0, arm, arm])


class Capsules(NamedTuple):
    """Capsules: axis ends ``(..., 6, 3)``, world, m, and radii ``(6,)``."""

    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray


def body_capsules(body: BodyModel, state: ArrayLike) -> Capsules:
    """Pose the body from keyframe values (:data:`~scara_collab.sim.person_scenarios.COLUMNS`).

    :param state: ``(..., 6)`` ``x, y, heading, lean, reach, phase``.
    :return: the capsules (:data:`SEGMENTS`), each of its fixed length (:attr:`BodyModel.lengths`).
    """
    s = np.asarray(state, dtype=float)
    x, y = s[..., _IX['x']], s[..., _IX['y']]
    heading, lean = s[..., _IX['heading']], s[..., _IX['lean']]
    reach, phase = s[..., _IX['reach']], s[..., _IX['phase']]
    zero = np.zeros_like(x)
    fwd = np.stack([np.cos(heading), np.sin(heading), zero], axis=-1)
    left = np.stack([-np.sin(heading), np.cos(heading), zero], axis=-1)
    up = np.array([0.0, 0.0, 1.0])
    centre = np.stack([x, y, zero], axis=-1)
    lengths = body.lengths
    # legs: from the hips down towards the feet, which swing fore and aft out of phase
    hip = centre + body.hip_height * up
    swing = (body.step_amplitude * np.sin(phase))[..., None]
    starts, ends = [], []
    for side, sign in ((1.0, 1.0), (-1.0, -1.0)):
        h = hip + side * body.stance * left
        foot = centre + side * body.stance * left + sign * swing * fwd + body.leg_radius * up
        axis = foot - h
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        starts.append(h)
        ends.append(h + lengths[0] * axis)
    # torso: from the hips up, leaning forward; the head on top
    torso_axis = (np.sin(lean)[..., None] * fwd + np.cos(lean)[..., None] * up)
    shoulders = hip + body.torso_length * torso_axis
    head = hip + (body.torso_length + body.neck) * torso_axis
    starts += [hip, head]
    ends += [shoulders, head]
    # arms: the left hangs, the right swings from hanging to reach_pitch below horizontal
    for side in (1.0, -1.0):
        shoulder = shoulders + side * body.shoulder_offset * left
        r = reach if side < 0 else zero
        angle = (-math.pi / 2.0 + r * (math.pi / 2.0 - body.reach_pitch))[..., None]
        direction = np.cos(angle) * fwd + np.sin(angle) * up
        starts.append(shoulder)
        ends.append(shoulder + lengths[4] * direction)
    return Capsules(np.stack(starts, axis=-2), np.stack(ends, axis=-2), body.radii)


def capsule_poses(caps: Capsules) -> np.ndarray:
    """Return one pose per capsule centre: ``(..., 6, 7)``, position and quaternion (x, y, z, w).

    The quaternion turns the z axis onto the capsule's axis (PyBullet's and a marker
    cylinder's axis); a sphere (zero length) keeps the identity.
    """
    centre = 0.5 * (caps.start + caps.end)
    axis = caps.end - caps.start
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    a = np.where(norm > 1e-12, axis / np.where(norm > 1e-12, norm, 1.0), [0.0, 0.0, 1.0])
    # the shortest rotation from z to a: axis z x a, angle acos(a_z), as a half-angle quaternion
    w = 1.0 + a[..., 2]
    quat = np.stack([-a[..., 1], a[..., 0], np.zeros_like(w), w], axis=-1)
    flip = w < 1e-9  # a = -z: half a turn about x
    quat = np.where(flip[..., None], [1.0, 0.0, 0.0, 0.0], quat)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    return np.concatenate([centre, quat], axis=-1)


def arm_distance(caps: Capsules, arm: ArmModel, q: ArrayLike) -> float:
    """Return the smallest surface distance of the body to an arm at ``q`` ``(3,)``, m.

    The cell's capsule distance (:func:`scara_collab.core.collision.capsule_distance`) over the
    6 x 3 pairs: the ground truth a benchmark scores ``S`` against.
    """
    a0, a1, ar = collision.arm_capsules(arm, q)
    d = collision.capsule_distance(caps.start[:, None], caps.end[:, None], caps.radius[:, None],
                                   a0[None], a1[None], ar[None])
    return float(d.min())


class Contact(NamedTuple):
    """A body segment touching an arm's link: ``(segment, link, depth in m, >= 0)``."""

    segment: str
    link: str
    depth: float


class PersonSim:
    """The person's body in a PyBullet world (module docstring).

    :param pb: the world's client (e.g. ``CellSim.client``).
    :param body: the body's sizes.
    :param path: the compiled scenario.
    :param cell_body: the cell's multibody (the arms, the fixed parts merged into its base).
    :param arm_links: ``{link index: link name}`` of the arms' moving links.
    """

    def __init__(self, pb, body: BodyModel, path: PersonPath, cell_body: int,
                 arm_links: dict):
        """Create one static capsule body per segment, parked, not colliding with the cell."""
        self.pb, self.body, self.path = pb, body, path
        self.cell_body, self.arm_links = cell_body, dict(arm_links)
        self.bodies: List[int] = []
        self.present = False
        self._caps: Optional[Capsules] = None
        lengths = body.lengths
        colour = [0.95, 0.8, 0.6, 1.0]
        for radius, length in zip(body.radii, lengths):
            if length > 0.0:
                shape = pb.createCollisionShape(pybullet.GEOM_CAPSULE, radius=float(radius),
                                                height=float(length))
                visual = pb.createVisualShape(pybullet.GEOM_CAPSULE, radius=float(radius),
                                              length=float(length), rgbaColor=colour)
            else:
                shape = pb.createCollisionShape(pybullet.GEOM_SPHERE, radius=float(radius))
                visual = pb.createVisualShape(pybullet.GEOM_SPHERE, radius=float(radius),
                                              rgbaColor=colour)
            uid = pb.createMultiBody(0.0, shape, visual, list(PARKED))
            for link in range(-1, pb.getNumJoints(cell_body)):
                pb.setCollisionFilterPair(uid, cell_body, -1, link, 0)
            self.bodies.append(uid)
        self._reset = pb.resetBasePositionAndOrientation

    def update(self, t: float) -> bool:
        """Pose the body for sim time ``t`` (or park it); return whether the person is there."""
        present = self.path.is_present(float(t))
        if present:
            self._caps = body_capsules(self.body, self.path.state(t))
            for uid, pose in zip(self.bodies, capsule_poses(self._caps).tolist()):
                self._reset(uid, pose[:3], pose[3:])
        elif self.present:
            self.park()
        self.present = present
        return present

    def park(self) -> None:
        """Move the body out of the world (below the floor)."""
        for uid in self.bodies:
            self._reset(uid, list(PARKED), [0.0, 0.0, 0.0, 1.0])
        self.present = False
        self._caps = None

    def capsules(self) -> Optional[Capsules]:
        """Return the body's capsules as posed by the last update, or None while away."""
        return self._caps

    def poses(self) -> np.ndarray:
        """Return one pose per capsule centre ``(6, 7)`` (empty ``(0, 7)`` while away)."""
        return np.zeros((0, 7)) if self._caps is None else capsule_poses(self._caps)

    def contacts(self, margin: float = 0.0) -> List[Contact]:
        """Return the segments touching (or within ``margin`` of) an arm's link, from PyBullet."""
        if self._caps is None:
            return []
        out = []
        for name, uid in zip(SEGMENTS, self.bodies):
            for pt in self.pb.getClosestPoints(uid, self.cell_body, margin):
                link = pt[4]
                if link in self.arm_links:
                    out.append(Contact(name, self.arm_links[link], max(0.0, -float(pt[8]))))
        return out

    def close(self) -> None:
        """Remove the body from the world."""
        for uid in self.bodies:
            try:
                self.pb.removeBody(uid)
            except pybullet.error:
                pass
        self.bodies = []


def arm_link_names(pb, cell_body: int, arms: Sequence[ArmModel]) -> dict:
    """Return ``{link index: link name}`` of the arms' moving links in the cell's multibody."""
    wanted = {f'{a.name}_{link}' for a in arms for link in ('link_1', 'link_2', 'quill')}
    out = {}
    for j in range(pb.getNumJoints(cell_body)):
        name = pb.getJointInfo(cell_body, j)[12].decode()
        if name in wanted:
            out[j] = name
    return out
