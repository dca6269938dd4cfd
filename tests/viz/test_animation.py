"""Animated missions: frame selection, belief look-up, detection flashes, sub-task labels,
the written GIF (frame count, size, timing) and the ``animate`` command."""

import io
import zipfile

import numpy as np
import pytest
import typer
from matplotlib.animation import writers
from PIL import Image
from typer.testing import CliRunner

from hptrack.cli.animate import register, write_animation
from hptrack.interface import InputError
from hptrack.registry import make_planner
from hptrack.sim.episode import run_episode
from hptrack.viz.animation import (
    animate_mission,
    detection_flash,
    frame_size_in,
    frame_steps,
    stored_belief_index,
    subtask_at,
)


def test_frame_steps_take_every_stride_and_the_last_step():
    assert frame_steps(120, 7).tolist() == list(range(0, 120, 7)) + [120]
    assert frame_steps(120, 10).tolist() == list(range(0, 121, 10))
    assert frame_steps(5, 1).tolist() == [0, 1, 2, 3, 4, 5]


def test_belief_is_the_stored_one_at_or_before_the_frame():
    stored = np.array([0, 10, 20, 25])
    steps = np.array([0, 5, 9, 10, 19, 24, 25])
    assert stored_belief_index(stored, steps).tolist() == [0, 0, 0, 1, 1, 2, 3]


def test_detection_flash_lights_the_frame_holding_it_then_fades():
    detections = np.zeros((11, 2), dtype=bool)
    detections[3, 0] = True  # between frames at steps 2 and 4
    detections[0, 1] = True
    strength = detection_flash(detections, np.arange(0, 11, 2), flash_frames=4)
    assert strength[:, 0].tolist() == [0.0, 0.0, 1.0, 0.75, 0.5, 0.25]
    assert strength[:, 1].tolist() == [1.0, 0.75, 0.5, 0.25, 0.0, 0.0]


def test_subtask_labels_follow_the_planner_log():
    info = {
        "subtasks": [
            {"target_index": 1, "start_step": 0, "end_step": 10, "outcome": "found"},
            {"target_index": 0, "start_step": 10, "end_step": 30, "outcome": "missed"},
            {"dwell": 1, "start_step": 30, "end_step": 35, "plan_after_dwell": 1},
            {"follow": 1, "start_step": 35},
        ]
    }
    labels, focus = subtask_at(info, ("a", "b"), np.array([0, 9, 10, 29, 30, 34, 35, 40]))
    assert labels == [
        "pursuing b",
        "pursuing b",
        "pursuing a",
        "pursuing a",
        "dwelling on b",
        "dwelling on b",
        "following b",
        "following b",
    ]
    assert focus.tolist() == [1, 1, 0, 0, 1, 1, 1, 1]
    ended = {
        "subtasks": [
            {"target_index": 0, "start_step": 0, "end_step": 5, "outcome": "missed"},
            {"follow": None, "start_step": 8},
        ]
    }
    labels, focus = subtask_at(ended, ("a",), np.array([4, 5, 8]))
    assert labels == ["pursuing a", "pursued a: missed", "hover"]
    assert focus.tolist() == [0, 0, -1]
    labels, focus = subtask_at({}, ("a",), np.array([0, 1]))
    assert labels == ["", ""] and focus.tolist() == [-1, -1]


def test_gif_has_one_frame_per_stride_and_the_figure_size(short_mission, tmp_path):
    _, record = short_mission
    path = tmp_path / "mission.gif"
    calls, encoded = [], []
    frames = animate_mission(
        record,
        path,
        stride=7,
        fps=10,
        progress=lambda done, total: calls.append((done, total)),
        encoding=lambda done, total: encoded.append((done, total, path.stat().st_size)),
    )
    assert frames == 19  # steps 0, 7, ..., 119, then 120
    assert calls == [(i, 19) for i in range(1, 20)]
    # then each frame encoded, before the file is written
    assert [(done, total) for done, total, _ in encoded] == [(i, 19) for i in range(1, 20)]
    assert all(size == 0 for *_, size in encoded)
    with Image.open(path) as gif:
        assert gif.n_frames == 19
        assert gif.size == (480, 532)  # 6 in x 6.65 in (map, title, legends) at 80 dpi
        assert gif.info["duration"] == 100  # ms at 10 fps
        gif.seek(0)
        first = np.asarray(gif.convert("RGB"))
        gif.seek(18)
        last = np.asarray(gif.convert("RGB"))
    assert (first != last).any()


def test_strided_beliefs_and_a_smaller_figure(short_mission, tmp_path):
    scenario, _ = short_mission
    record = run_episode(scenario, make_planner("greedy"), belief_stride=25)
    assert record.belief_steps.tolist() == [0, 25, 50, 75, 100, 120]
    path = tmp_path / "small.gif"
    assert animate_mission(record, path, stride=30, dpi=40, size_in=4.0) == 5
    with Image.open(path) as gif:
        assert gif.n_frames == 5 and gif.size == (160, 186)  # 4 in x 4.65 in at 40 dpi


def test_frame_height_fits_the_square_map_and_one_legend_row_per_eight_targets():
    width, height = frame_size_in(6.0, 2)
    assert width == 6.0
    assert height == pytest.approx(6.0 - 0.75 - 0.3 + 0.3 + 0.5 + 0.45 + 0.25 + 0.2)
    assert frame_size_in(6.0, 8)[1] == height
    assert frame_size_in(6.0, 9)[1] == pytest.approx(height + 0.2)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"stride": 0}, ["stride", "0"]),
        ({"fps": 0}, ["fps", "0"]),
        ({"trail_s": -1.0}, ["trail_s", "-1"]),
    ],
)
def test_bad_settings_are_input_errors(short_mission, tmp_path, kwargs, words):
    with pytest.raises(InputError) as err:
        animate_mission(short_mission[1], tmp_path / "m.gif", **kwargs)
    assert all(w in str(err.value) for w in words) and "\n" not in str(err.value)


def test_unknown_format_and_missing_ffmpeg_are_input_errors(short_mission, tmp_path, monkeypatch):
    with pytest.raises(InputError, match=r"unknown animation format '\.avi'"):
        animate_mission(short_mission[1], tmp_path / "m.avi")
    monkeypatch.setattr(writers, "is_available", lambda name: False)
    with pytest.raises(InputError, match="ffmpeg is not installed.*use a .gif file"):
        animate_mission(short_mission[1], tmp_path / "m.mp4")
    assert not (tmp_path / "m.mp4").exists()


@pytest.mark.skipif(not writers.is_available("ffmpeg"), reason="ffmpeg is not installed")
def test_mp4_with_ffmpeg(short_mission, tmp_path):
    path = tmp_path / "m.mp4"
    assert animate_mission(short_mission[1], path, stride=20) == 7
    assert path.stat().st_size > 0


@pytest.fixture
def cli():
    app = typer.Typer()

    @app.callback()
    def main() -> None:
        """Test app holding only the animate command."""

    register(app)
    return lambda args: CliRunner().invoke(app, args)


def test_animate_command_writes_the_gif(cli, short_mission, tmp_path):
    record_path = tmp_path / "m.npz"
    short_mission[1].save(record_path)
    out = tmp_path / "out" / "m.gif"
    result = cli(["animate", str(record_path), "-o", str(out), "--stride", "12", "--fps", "5"])
    assert result.exit_code == 0, result.output
    assert "11 frames" in result.output
    with Image.open(out) as gif:
        assert gif.n_frames == 11 and gif.info["duration"] == 200


def test_write_animation_returns_the_frames(short_mission, tmp_path):
    assert write_animation(short_mission[1], tmp_path / "w.gif", stride=60, fps=4) == 3


def _input_error(result) -> str:
    """The one-line InputError the command raised (``hptrack.cli.app.main`` prints it and
    exits 2)."""
    assert isinstance(result.exception, InputError), result.output
    message = str(result.exception)
    assert "\n" not in message
    return message


def test_animate_command_input_errors(cli, short_mission, tmp_path, monkeypatch):
    good = tmp_path / "m.npz"
    short_mission[1].save(good)
    line = _input_error(cli(["animate", str(tmp_path / "none.npz")]))
    assert "none.npz" in line and "no such file" in line
    text = tmp_path / "text.npz"
    text.write_text("not a record")
    line = _input_error(cli(["animate", str(text)]))
    assert "text.npz" in line and "not an hptrack episode record" in line
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    line = _input_error(cli(["animate", str(other)]))
    assert "other.npz" in line and "not an hptrack episode record" in line
    partial = tmp_path / "partial.npz"
    with np.load(good) as data:
        np.savez(partial, meta=data["meta"])  # the metadata but none of the arrays
    line = _input_error(cli(["animate", str(partial)]))
    assert "partial.npz" in line and "agent_path" in line
    line = _input_error(cli(["animate", str(good), "--stride", "0"]))
    assert "--stride" in line and "0" in line
    line = _input_error(cli(["animate", str(good), "--fps", "0"]))
    assert "--fps" in line
    line = _input_error(cli(["animate", str(good), "-o", str(tmp_path / "m.avi")]))
    assert "--output" in line and "'.avi'" in line
    monkeypatch.setattr(writers, "is_available", lambda name: False)
    line = _input_error(cli(["animate", str(good), "-o", str(tmp_path / "m.mp4")]))
    assert "--output" in line and "ffmpeg" in line and ".gif" in line
    (tmp_path / "folder.gif").mkdir()
    line = _input_error(cli(["animate", str(good), "-o", str(tmp_path / "folder.gif")]))
    assert "--output" in line and "folder" in line


def test_an_array_whose_header_declares_a_huge_shape_is_refused_unread(
    cli, short_mission, tmp_path
):
    good = tmp_path / "m.npz"
    short_mission[1].save(good)
    forged = tmp_path / "forged.npz"
    with zipfile.ZipFile(good) as source, zipfile.ZipFile(forged, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "agent_paths.npy":  # say 238 GiB, hold a few kB
                header = np.lib.format.header_data_from_array_1_0(np.zeros(1))
                header["shape"] = (4_000_000, 8_000)
                buffer = io.BytesIO()
                np.lib.format.write_array_header_1_0(buffer, header)
                data = buffer.getvalue() + data[len(buffer.getvalue()) :]
            target.writestr(item, data)
    line = _input_error(cli(["animate", str(forged)]))
    assert "forged.npz" in line
    assert "agent_paths.npy declares an array of shape (4000000, 8000)" in line
    assert "256,000,000,000 bytes" in line
