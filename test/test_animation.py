"""The run animation: a short recorded run rendered to a GIF that shows the arms and the items.

The run is recorded in-process (test_mcap_log.record_run: the bridge, the run recorder and its
MCAP log; the left arm makes a joint move, items are fed). Where the arms and the items are in
a frame is found independently: the same scene posed from ``timeseries.csv`` and rendered
with PyBullet's segmentation mask; the "empty scene" is that scene with the arm links made
transparent and no items. A person is a recording of ``/person/markers`` written beside the
same run's files, found the same way.
"""
from pathlib import Path
import shutil
import subprocess
import sys

import numpy as np
from PIL import Image
import pybullet
import pytest
from rclpy.serialization import serialize_message
from test_mcap_log import record_run
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.graph import Topic
from scara_collab.records import report
from scara_collab.records.mcap_log import McapWriter
from scara_collab.run.animation import (
    CAPTION_HEIGHT, decode_items, decode_person, frame_times, load_items, PERSON_TOPIC,
    render_after_run, render_gif, RenderScene)

ROOT = Path(__file__).resolve().parents[1]
FPS = 3.0
ARM_PARTS = ('base_link', 'link_1', 'link_2', 'quill')


@pytest.fixture(scope='module')
def run_dir(tmp_path_factory, cell):
    """Record a 2.5 s run in-process once; return its folder."""
    directory = tmp_path_factory.mktemp('anim_run')
    record_run(directory, cell, seconds=2.5)
    return directory


@pytest.fixture(scope='module')
def gif(run_dir):
    """Render the run folder to a GIF at 3 fps once; return its path."""
    return render_gif(run_dir, fps=FPS, max_seconds=10.0)


def gif_frames(path: Path):
    """Return a GIF's frames as RGB int arrays and their durations, ms."""
    with Image.open(path) as im:
        frames, durations = [], []
        for k in range(im.n_frames):
            im.seek(k)
            durations.append(im.info.get('duration'))
            frames.append(np.asarray(im.convert('RGB'), dtype=int))
    return frames, durations


def arm_links(scene: RenderScene):
    """Return the scene's arm link indices, each mapped to its robot."""
    pb, body = scene.pb, scene.cell_body
    names = {pb.getJointInfo(body, j)[12].decode(): j for j in range(pb.getNumJoints(body))}
    wanted = {f'{arm.name}_{part}': arm.name for arm in scene.cell.arms for part in ARM_PARTS}
    return {j: wanted[n] for n, j in names.items() if n in wanted}


def segmentation(scene: RenderScene) -> np.ndarray:
    """Return PyBullet's segmentation mask (object and link index) of the scene's camera."""
    _, _, _, _, seg = scene.pb.getCameraImage(
        scene.width, scene.height, scene.view_matrix, scene.projection_matrix,
        renderer=pybullet.ER_TINY_RENDERER,
        flags=pybullet.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX)
    return np.reshape(np.asarray(seg, dtype=np.int64), (scene.height, scene.width))


def test_frame_times_make_a_bounded_time_lapse():
    """Frame times span the job window at ``fps``, thinned to ``max_seconds`` of GIF."""
    np.testing.assert_allclose(frame_times(0.0, 2.0, fps=10, max_seconds=30), np.arange(21) / 10)
    long = frame_times(10.0, 130.0, fps=10, max_seconds=30)
    assert len(long) == 300 and long[0] == 10.0 and long[-1] == 130.0
    np.testing.assert_allclose(frame_times(5.0, 5.0), [5.0])


def test_the_gif_shows_the_moving_arms_and_the_items(run_dir, gif, cell):
    """The GIF shows the moving arms and the items, and nothing else differs.

    Where they are is found independently: the same scene posed from the run's files and
    rendered with a segmentation mask.
    """
    summary = report.read_summary(run_dir)
    times = frame_times(summary['job_start_sim_time'], summary['sim_time_end'], FPS, 10.0)
    frames, durations = gif_frames(gif)
    assert gif == run_dir / 'run.gif'
    assert len(frames) == len(times) >= 5
    assert frames[0].shape == (360 + CAPTION_HEIGHT, 640, 3)
    assert all(abs(d - 1000 / FPS) <= 10 for d in durations)  # GIF stores centiseconds
    ts = report.load_timeseries(run_dir)
    names = [n for arm in cell.arms for n in arm.joint_names]
    q = np.stack([ts[n] for n in names], axis=1)
    item_t, item_data, reading = load_items(run_dir / 'run.mcap')
    assert reading.complete and len(item_data) > 5
    masks = []
    with RenderScene(cell) as scene:
        links = arm_links(scene)
        assert sorted(set(links.values())) == sorted(a.name for a in cell.arms)
        for k in (0, len(frames) - 1):
            row = max(0, int(np.searchsorted(ts['t'], times[k], side='right')) - 1)
            scene.pose(q[row, :3], q[row, 3:])
            j = int(np.searchsorted(item_t, times[k], side='right')) - 1
            scene.set_items(decode_items(item_data[j]))
            seg = segmentation(scene)
            obj, link = seg & ((1 << 24) - 1), (seg >> 24) - 1
            arm = (obj == scene.cell_body) & np.isin(link, list(links))
            items = np.isin(obj, list(scene.items.values()))
            # the empty scene: arms transparent, no items
            for j_link in links:
                scene.pb.changeVisualShape(scene.cell_body, j_link, rgbaColor=[1, 1, 1, 0])
            scene.set_items([])
            empty = scene.render().astype(int)
            for j_link in links:
                scene.pb.changeVisualShape(scene.cell_body, j_link, rgbaColor=[1, 0.5, 0, 1])
            frame = frames[k][:scene.height]
            differs = np.abs(frame - empty).sum(axis=-1) > 40
            print(f'\nframe {k}: {arm.sum()} arm pixels, {differs[arm].mean():.1%} differ from '
                  f'the empty scene; {items.sum()} item pixels, {differs[items].sum()} '
                  f'differ; elsewhere {differs[~arm & ~items].mean():.2%} differ')
            assert arm.sum() > 2000, 'both arms are in view'
            assert differs[arm].mean() > 0.9, 'the GIF shows the arms where the scene has them'
            if k > 0:  # items arrive every 0.4 s from the start of the bridge
                assert items.sum() > 20 and differs[items].mean() > 0.8, 'and the items'
            assert differs[~arm & ~items].mean() < 0.01, 'and nothing else differs'
            masks.append(arm)
    moved = masks[0] ^ masks[1]
    assert moved.sum() > 500, 'the left arm moved during the run'
    change = np.abs(frames[0] - frames[-1])[:360].sum(axis=-1) > 40
    assert change[moved].mean() > 0.8


def test_render_run_script_and_the_launcher_hook(run_dir, tmp_path):
    """``render_run.py`` writes a GIF of the asked size; the launcher hook reports and stops.

    The hook says why a run without files is not rendered, and stops when asked to.
    """
    out = tmp_path / 'small.gif'
    proc = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'render_run.py'),
                           str(run_dir), '--output', str(out), '--fps', '2', '--size',
                           '160x90'], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert '[animation]' in proc.stdout and 'items from run.mcap' in proc.stdout
    with Image.open(out) as im:
        assert im.size == (160, 90 + CAPTION_HEIGHT) and im.n_frames >= 5
    said = []
    assert render_after_run(tmp_path / 'no_run', said.append) is None
    assert said and 'not rendered' in said[-1]
    said.clear()
    copy = shutil.copytree(run_dir, tmp_path / 'copy', ignore=shutil.ignore_patterns('*.gif'))
    polls = []
    stopped = render_after_run(copy, said.append, stop=lambda: polls.append(1) or len(polls) > 2)
    assert stopped == copy / 'run.gif' and any('stopped after 2 of' in s for s in said)
    with Image.open(stopped) as im:
        assert im.n_frames == 2


def body_markers(x: float, y: float) -> MarkerArray:
    """Return a standing person at ``(x, y)`` as the bridge draws one.

    A DELETEALL, a torso cylinder with its sphere ends and a leg, and a text marker the GIF
    leaves out.
    """
    out = MarkerArray(markers=[Marker(action=Marker.DELETEALL)])
    parts = [(Marker.CYLINDER, 1.2, 0.34, 0.55), (Marker.SPHERE, 0.925, 0.34, 0.34),
             (Marker.SPHERE, 1.475, 0.34, 0.34), (Marker.CYLINDER, 0.45, 0.14, 0.9),
             (Marker.TEXT_VIEW_FACING, 2.0, 0.1, 0.1)]
    for k, (kind, z, width, height) in enumerate(parts):
        m = Marker(ns='person', id=k, type=kind, action=Marker.ADD)
        m.header.frame_id = 'world'
        m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, z
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = width
        m.scale.z = height
        m.color.r, m.color.g, m.color.b, m.color.a = 0.95, 0.8, 0.6, 1.0
        out.markers.append(m)
    return out


def test_person_markers_decode_to_the_shapes_the_scene_draws():
    """Cylinders and spheres added in ``world`` are kept, by scale, colour and pose."""
    shapes = decode_person(serialize_message(body_markers(1.0, -2.0)))
    assert [s.kind for s in shapes] == ['cylinder', 'sphere', 'sphere', 'cylinder']
    assert shapes[0].size == (0.34, 0.34, 0.55) and shapes[0].rgba == (0.95, 0.8, 0.6, 1.0)
    assert shapes[1].position == (1.0, -2.0, 0.925) and shapes[1].quat == (0.0, 0.0, 0.0, 1.0)
    assert decode_person(serialize_message(MarkerArray(markers=[
        Marker(action=Marker.DELETEALL)]))) == []


def test_a_recorded_person_is_in_the_gif(run_dir, cell, tmp_path):
    """With ``/person/markers`` in run.mcap the GIF shows the person where the markers say.

    Found independently: the scene posed as the first frame, the person's bodies picked out of
    the segmentation mask; the GIF differs from the scene without the person there only.
    """
    copy = tmp_path / 'run'
    copy.mkdir()
    for name in ('timeseries.csv', 'summary.json', 'events.csv'):
        shutil.copy(run_dir / name, copy / name)
    summary = report.read_summary(copy)
    t0 = summary['job_start_sim_time']
    markers = body_markers(1.0, -2.2)
    topic = Topic(PERSON_TOPIC, 'visualization_msgs/msg/MarkerArray')
    writer = McapWriter(copy / 'run.mcap', [topic])
    writer.write([(int(t0 * 1e9), 0, serialize_message(markers))])
    writer.close()
    said = []
    frames, _ = gif_frames(render_gif(copy, fps=FPS, max_seconds=10.0, progress=said.append))
    assert any('a person from /person/markers' in line for line in said)
    ts = report.load_timeseries(copy)
    q = np.stack([ts[n] for arm in cell.arms for n in arm.joint_names], axis=1)
    row = max(0, int(np.searchsorted(ts['t'], t0, side='right')) - 1)
    with RenderScene(cell) as scene:
        scene.pose(q[row, :3], q[row, 3:])
        scene.set_person(decode_person(serialize_message(markers)))
        assert len(scene.person) == 4
        seg = segmentation(scene)
        person = np.isin(seg & ((1 << 24) - 1), [body for _, body in scene.person])
        scene.set_person([])
        empty = scene.render().astype(int)
    differs = np.abs(frames[0][:scene.height] - empty).sum(axis=-1) > 40
    print(f'\n{person.sum()} person pixels, {differs[person].mean():.1%} differ from the '
          f'empty scene; elsewhere {differs[~person].mean():.2%}')
    assert person.sum() > 500, 'the person is in view'
    assert differs[person].mean() > 0.9 and differs[~person].mean() < 0.01
