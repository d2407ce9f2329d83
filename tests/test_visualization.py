"""The Meshcat replay of a run (diagrams/views/replay.py) and the Graphviz picture of the loop
(diagrams/views/picture.py).

The replay is checked by decoding the Meshcat commands stored in the HTML: the animation
must pose the arm at the logged joint positions, put the wall's face at Xe(t) and draw the
force arrow with a length proportional to the force, in a 2-D view of the x-y plane.
"""

from __future__ import annotations

import re
import struct

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from pydrake.systems.framework import DiagramBuilder
from replay_data import replay_commands, replay_tracks

import admittance.diagrams.robots.planar_arm.replay as arm_replay
import admittance.diagrams.robots.spatial_arm.replay as spatial_replay_module
import admittance.diagrams.views.picture as picture
import admittance.diagrams.views.replay as visualization
from admittance.diagrams.app.cli import main
from admittance.diagrams.robots.planar_arm.loop import BuildClosedLoop
from admittance.diagrams.robots.planar_arm.plant import AddScenarioArm
from admittance.diagrams.robots.planar_arm.replay import write_meshcat_replay
from admittance.diagrams.robots.planar_arm.run import run_scenario
from admittance.diagrams.robots.spatial_arm.plant import example_robot_data_packages
from admittance.diagrams.scenario.files import load_scenario
from admittance.diagrams.views.picture import DiagramPictureError, write_diagram_picture

# The paper's Fig. 1 blocks, as named by BuildClosedLoop, and some of their ports.
FIG1_BLOCKS = [
    "desired_trajectory",
    "optimal_admittance",
    "commanded_position",
    "cartesian_pid",
    "plant",
    "compliant_wall",
    "flexiforce_sensor",
    "force_reference",
]
FIG1_PORTS = ["measured_force", "desired_force", "reference_offset", "actuation", "contact_force"]


@pytest.fixture(scope="module")
def moving_wall_result():
    """Half a second of the moving-wall run, the wall moving from 0.1 s to 0.4 s."""
    overrides = ["duration=0.5", "wall.motion_start=0.1", "wall.motion_end=0.4"]
    return run_scenario(load_scenario("paper_moving_wall", overrides))


@pytest.fixture(scope="module")
def replay(moving_wall_result, tmp_path_factory):
    """(path, html, decoded Meshcat commands) of the run's replay."""
    path = tmp_path_factory.mktemp("replay") / "sub" / "replay.html"
    written = write_meshcat_replay(moving_wall_result, path)
    assert written == path
    html = path.read_text(encoding="utf-8")
    return path, html, replay_commands(html)


def test_replay_html_is_self_contained(replay):
    path, html, commands = replay
    assert path.is_file() and html.lstrip().startswith("<!DOCTYPE html>")
    # The Meshcat viewer itself is inlined ...
    assert "MeshCat" in html and len(html) > 500_000
    # ... no tag loads anything ...
    for tag in re.findall(r"<(?:script|link|img|iframe|source|embed)\b[^>]*>", html, re.I):
        assert not re.search(r"\b(?:src|href)\s*=", tag, re.I), tag
    # ... and every command is fetched from a data: URL, not from a server.
    fetched = re.findall(r'fetch\(\s*["\']([^"\']*)', html)
    assert fetched and all(url.startswith("data:") for url in fetched)
    assert len(commands) == len([url for url in fetched if "octet-binary" in url]) > 10


def test_replay_poses_the_arm_at_the_logged_joint_positions(replay, moving_wall_result):
    _, _, commands = replay
    tracks = replay_tracks(commands)
    times = visualization.frame_times(moving_wall_result.time)
    assert times[0] == 0.0 and times[-1] == pytest.approx(0.5)
    assert len(times) == 0.5 * visualization.REPLAY_FRAMES_PER_SECOND + 1

    builder = DiagramBuilder()
    plant, _ = AddScenarioArm(builder, moving_wall_result.scenario.arm)
    context = plant.CreateDefaultContext()
    arm_paths = [path for path, prop in tracks if "planar_arm/link" in path and prop == "position"]
    assert sorted(p.rsplit("/", 1)[-1] for p in arm_paths) == ["link1", "link2", "link3"]
    for frame in (0, len(times) // 2, len(times) - 1):
        q = [
            np.interp(times[frame], moving_wall_result.time, column)
            for column in moving_wall_result.joint_positions.T
        ]
        plant.SetPositions(context, q)
        for arm_path in arm_paths:
            keys = tracks[(arm_path, "position")]
            assert [k["time"] for k in keys] == list(range(len(times)))
            body = plant.GetBodyByName(arm_path.rsplit("/", 1)[-1])
            expected = plant.EvalBodyPoseInWorld(context, body).translation()
            np.testing.assert_allclose(keys[frame]["value"], expected, atol=1e-9)


def test_replay_draws_the_wall_at_its_position_and_the_force_to_scale(replay, moving_wall_result):
    _, _, commands = replay
    tracks = replay_tracks(commands)
    result = moving_wall_result
    times = visualization.frame_times(result.time)

    # The wall slab's face is at Xe(t), and it moves (1.5 mm between 0.1 s and 0.4 s).
    wall = tracks[(arm_replay.WALL_PATH, "position")]
    face = np.array([k["value"][0] for k in wall]) - 0.5 * arm_replay.WALL_THICKNESS
    np.testing.assert_allclose(face, np.interp(times, result.time, result.wall_position))
    assert face[-1] - face[0] == pytest.approx(0.005 * 0.3)

    # The arrow starts at the fingertip; its apex (the cone's origin) lies a force-
    # proportional length further along +x; it is hidden while there is no force.
    force = np.interp(times, result.time, result.force)
    tip_x = np.interp(times, result.time, result.pose[:, 0])
    head = np.array([k["value"] for k in tracks[(f"{visualization.FORCE_PATH}/head", "position")]])
    length = head[:, 0] - tip_x
    visible = [k["value"] for k in tracks[(visualization.FORCE_PATH, "visible")]]
    assert force[0] == 0.0 and visible[0] is False
    assert all(visible[1:]) and np.all(force[1:] > 1.0)
    scale = length[1:] / force[1:]
    # The drawing scale: 1 cm per newton, unless the peak force would draw longer than the
    # longest arrow (then that length over the peak). Lengths and forces pass through float
    # interpolation and subtraction: they agree to about 1e-15 relative (measured 2e-16),
    # 1e-9 leaves room for any rounding and none for a wrong scale.
    expected = min(
        visualization.FORCE_ARROW_METERS_PER_NEWTON,
        visualization.FORCE_ARROW_MAX_LENGTH / np.max(force),
    )
    np.testing.assert_allclose(scale, expected, rtol=1e-9)
    assert np.max(length) <= visualization.FORCE_ARROW_MAX_LENGTH + 1e-12
    # The Fr tick is drawn on the same scale.
    tick = tracks[(visualization.FORCE_REFERENCE_PATH, "position")]
    assert tick[-1]["value"][0] - tip_x[-1] == pytest.approx(scale[0] * result.force_reference)


def test_replay_view_is_the_x_y_plane_with_x_right_and_y_up(replay, moving_wall_result):
    _, _, commands = replay
    (camera,) = [
        c for c in commands if c["type"] == "set_object" and c["path"] == "/Cameras/default/rotated"
    ]
    camera = camera["object"]["object"]
    assert camera["type"] == "OrthographicCamera"
    (pose,) = [
        c for c in commands if c["type"] == "set_transform" and c["path"] == "/Cameras/default"
    ]
    X_WC = np.array(pose["matrix"]).reshape(4, 4).T  # three.js matrices are column-major
    # Drake's 2-D mode draws the camera's +x to the right and its +z up.
    np.testing.assert_allclose(X_WC[:3, 0], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(X_WC[:3, 2], [0, 1, 0], atol=1e-12)
    # The view holds the whole arm (the base at the origin, the fingertip) and the wall.
    left, right = X_WC[0, 3] + camera["left"], X_WC[0, 3] + camera["right"]
    bottom, top = X_WC[1, 3] + camera["bottom"], X_WC[1, 3] + camera["top"]
    x, y = moving_wall_result.pose[:, 0], moving_wall_result.pose[:, 1]
    assert left < 0.0 < right and bottom < 0.0 < top
    assert left < x.min() and x.max() + arm_replay.WALL_THICKNESS < right
    assert bottom < y.min() and y.max() < top


# ------------------------------------------------------------------- spatial replay

needs_robots = pytest.mark.skipif(
    example_robot_data_packages() is None,
    reason='example-robot-data is not installed: pip install "optimal-admittance[robots]"',
)
# The follow task shortened: approach 1 s, force ramp 1 s, press 0.5 s, so the slide starts
# at 2.5 s; 2 cm out at 2 cm/s with 0.5 s cubic blends reaches 1 cm at 3.25 s (by symmetry
# of the out leg, 0.5 v b + v (0.75 - 0.5) = 5 mm + 5 mm) and stops at 2 cm at 4.0 s.
SHORT_FOLLOW = ["trajectory.press_time=0.5", "trajectory.slide_distance=0.02", "duration=4.0"]
SLIDE_TIMES = (2.5, 3.25, 4.0)
SLIDE_X = (0.0, 0.01, 0.02)
# panda_surface_follow's planned contact point (surface.position, surface.height), its Fr,
# the tool (a 1 cm sphere on a 15 cm shaft: the tip 16 cm from the flange along its z) and
# the table's thickness (robots.spatial_arm.plant.TABLE_SIZE).
CONTACT = np.array([0.45, -0.05, 0.2])
FORCE_REFERENCE = 10.0
SURFACE_STIFFNESS = 1e5
TIP_OFFSET = 0.15 + 0.01
TABLE_THICKNESS = 0.05


@pytest.fixture(scope="module")
def spatial_replay(tmp_path_factory):
    """The decoded Meshcat commands of the short follow's replay, written by
    `admittance simulate --meshcat-html` (through views.figures.write_replay)."""
    folder = tmp_path_factory.mktemp("spatial_replay")
    path = folder / "replay.html"
    overrides = [argument for key in SHORT_FOLLOW for argument in ("--set", key)]
    arguments = ["simulate", "panda_surface_follow", *overrides, "-q"]
    assert main([*arguments, "--out", str(folder / "run"), "--meshcat-html", str(path)]) == 0
    return replay_commands(path.read_text(encoding="utf-8"))


def _objects(commands, part: str) -> list[dict]:
    return [c for c in commands if c["type"] == "set_object" and part in c["path"]]


@needs_robots
def test_spatial_replay_holds_the_arms_meshes_the_tool_and_the_table(spatial_replay):
    # Every link of the Panda and its hand, drawn from its own Collada mesh.
    for link in [f"panda_link{i}" for i in range(8)] + ["panda_hand"]:
        (mesh,) = _objects(spatial_replay, f"/drake/visualizer/panda/{link}/")
        (geometry,) = mesh["object"]["geometries"]
        assert geometry["type"] == "_meshfile_geometry" and geometry["format"] == "dae"
        assert "<COLLADA" in geometry["data"][:500]
    # The tool's sphere (1 cm) and the table: a box whose top is at the planned height (no
    # height error or tilt here), centred under the planned contact point.
    (sphere,) = _objects(spatial_replay, "/tool/tool_visual")
    assert sphere["object"]["geometries"][0]["radius"] == pytest.approx(0.01)
    (table,) = _objects(spatial_replay, "/table/table_visual")
    assert table["object"]["geometries"][0]["type"] == "BoxGeometry"
    tracks = replay_tracks(spatial_replay)
    table_position = tracks[("/drake/visualizer/table/table", "position")][0]["value"]
    np.testing.assert_allclose(
        table_position, CONTACT - [0.0, 0.0, 0.5 * TABLE_THICKNESS], atol=1e-12
    )


@needs_robots
def test_spatial_replay_tool_moves_along_the_slide_and_presses_fr(spatial_replay):
    tracks = replay_tracks(spatial_replay)
    position = tracks[("/drake/visualizer/tool/tool", "position")]
    quaternion = tracks[("/drake/visualizer/tool/tool", "quaternion")]
    commanded = tracks[(visualization.COMMANDED_PATH, "position")]
    head = tracks[(f"{visualization.FORCE_PATH}/head", "position")]
    for t, x in zip(SLIDE_TIMES, SLIDE_X, strict=True):
        frame = int(round(t * visualization.REPLAY_FRAMES_PER_SECOND))
        assert position[frame]["time"] == frame
        qx, qy, qz, qw = quaternion[frame]["value"]  # three.js order
        R_WT = RotationMatrix(Quaternion(qw, qx, qy, qz))
        tip = np.array(position[frame]["value"]) + R_WT.col(2) * TIP_OFFSET
        # The plan, slid by x along world x (slide_direction 0), Fr / k = 0.1 mm into the
        # table's top (the sphere's linear contact stiffness, surface.stiffness = 1e5 N/m).
        # Tolerance: measured 7 um in the plane and 0.3 um in depth; 0.1 mm is 14 times that
        # and a fifth of a frame's slide at full speed (2 cm/s / 32 frames/s = 0.6 mm).
        expected = CONTACT + [x, 0.0, -FORCE_REFERENCE / SURFACE_STIFFNESS]
        np.testing.assert_allclose(tip, expected, atol=1e-4)
        # The commanded position (green dot) is the plan's x exactly.
        assert commanded[frame]["value"][0] == pytest.approx(CONTACT[0] + x, abs=1e-9)
        # The force arrow points down into the table, Fr long at 1 cm/N (the force within
        # 1 % of Fr: measured 0.3 %).
        arrow = tip - np.array(head[frame]["value"])
        np.testing.assert_allclose(arrow[:2], 0.0, atol=1e-9)
        assert arrow[2] == pytest.approx(
            FORCE_REFERENCE * spatial_replay_module.ARROW_METERS_PER_NEWTON, rel=0.01
        )


# ------------------------------------------------------------------- diagram picture


@pytest.fixture(scope="module")
def loop_diagram():
    return BuildClosedLoop(load_scenario("paper_moving_wall")).diagram


# The connections of paper_moving_wall's loop, counted by hand from the paper's Fig. 1 and
# BuildClosedLoop: plant <-> scene_graph (2 + 1), plant -> fingertip kinematics, kinematics
# -> wall, wall -> plant, kinematics -> PID, PID -> plant, wall -> sensor, noise source ->
# gain -> sensor (2), sensor -> admittance, Fr -> admittance, Xd and Xr -> commanded position
# (2), commanded position and dXd/dt -> PID (2). The six loggers' connections are not drawn.
MOVING_WALL_CONNECTIONS = 17


def test_diagram_dot_source_names_the_fig1_blocks(loop_diagram, tmp_path):
    path = write_diagram_picture(loop_diagram, tmp_path / "loop.dot")
    assert path == tmp_path / "loop.dot"
    source = path.read_text()
    assert source.startswith("digraph")
    for name in FIG1_BLOCKS:
        assert f"<B>{name}</B>" in source
    for port in FIG1_PORTS:
        assert f">{port}<" in source
    assert source.count("->") == MOVING_WALL_CONNECTIONS


def test_diagram_leaves_out_loggers_scalar_types_and_unconnected_ports(loop_diagram, tmp_path):
    source = write_diagram_picture(loop_diagram, tmp_path / "loop.dot").read_text()
    assert "VectorLogSink" not in source and "log_state" not in source
    assert "CompliantWall<" in source  # the class, without module or scalar type
    assert "admittance.systems" not in source and "float" not in source
    # The plant shows its connected ports only, and says how many it leaves out.
    assert ">state<" in source and ">body_poses<" not in source
    assert "unconnected ports not shown" in source


def test_diagram_drake_style_is_drakes_own_rendering(loop_diagram, tmp_path):
    path = write_diagram_picture(loop_diagram, tmp_path / "loop.dot", style="drake")
    assert path.read_text() == loop_diagram.GetGraphvizString(max_depth=1)
    with pytest.raises(ValueError, match="readable, drake"):
        write_diagram_picture(loop_diagram, tmp_path / "other.dot", style="full")
    assert not (tmp_path / "other.dot").exists()


def test_diagram_svg_names_the_fig1_blocks_and_ports(loop_diagram, tmp_path):
    path = write_diagram_picture(loop_diagram, tmp_path / "pictures" / "loop.svg")
    svg = path.read_text()
    assert "<svg" in svg
    for name in FIG1_BLOCKS:
        assert f">{name}<" in svg
    for port in FIG1_PORTS:
        assert f">{port}<" in svg
    assert [p.name for p in path.parent.iterdir()] == ["loop.svg"]  # no staging file left


def test_diagram_png_reads_at_a_page_width(loop_diagram, tmp_path):
    data = write_diagram_picture(loop_diagram, tmp_path / "loop.PNG").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    # Measured 1,063 x 1,051 pixels for this loop (Drake's own rendering: 3,475 x 968).
    # A page shows about 900 pixels; up to 1,300 its 11-point text stays above 10 pixels.
    assert 600 < width <= 1300 and height > 600


def test_diagram_picture_refuses_an_unknown_suffix(loop_diagram, tmp_path):
    with pytest.raises(ValueError, match=r"\.svg, \.png, \.dot"):
        write_diagram_picture(loop_diagram, tmp_path / "loop.pdf")
    assert not any(tmp_path.iterdir())


def test_diagram_picture_without_a_renderer_says_so_in_one_line(
    loop_diagram, tmp_path, monkeypatch
):
    monkeypatch.setattr(picture, "_graphviz_command", lambda: None)
    with pytest.raises(DiagramPictureError, match="pip install graphviz-pure") as error:
        write_diagram_picture(loop_diagram, tmp_path / "loop.png")
    assert "\n" not in str(error.value) and "loop.png" in str(error.value)
    assert not any(tmp_path.iterdir())
    # The DOT source needs no renderer.
    assert write_diagram_picture(loop_diagram, tmp_path / "loop.dot").is_file()


def test_diagram_picture_reports_a_failing_renderer(loop_diagram, tmp_path, monkeypatch):
    monkeypatch.setattr(picture, "_graphviz_command", lambda: "/bin/false")
    with pytest.raises(DiagramPictureError, match="false failed") as error:
        write_diagram_picture(loop_diagram, tmp_path / "loop.svg")
    assert "\n" not in str(error.value)
    assert not any(tmp_path.iterdir())
