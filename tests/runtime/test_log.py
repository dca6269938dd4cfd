import json
import math

import numpy as np
import pytest

from hptrack.interface import InputError
from hptrack.runtime.log import LOG_VERSION, MissionLog, json_ready, log_array, read_log


def test_non_finite_numbers_are_strict_json_and_read_back():
    data = json_ready({"p": np.array([math.nan, math.inf, -1.5]), "n": np.int64(3)})
    assert data == {"p": ["nan", "inf", -1.5], "n": 3}
    back = log_array(data["p"])
    assert math.isnan(back[0]) and back[1] == math.inf and back[2] == -1.5


def _write(path, n):
    log = MissionLog(path)
    log.write({"kind": "header", "version": LOG_VERSION})
    for i in range(n):
        log.write({"kind": "odometry", "t": 0.1 * i, "position": [i, 0.0]})
    log.close()


def test_every_line_is_flushed_as_written(tmp_path):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    log.write({"kind": "header", "version": LOG_VERSION})
    log.write({"kind": "odometry", "t": 0.0})
    lines = path.read_text().splitlines()  # read while the log is still open
    assert [json.loads(line)["seq"] for line in lines] == [0, 1]
    log.close()


def test_a_truncated_last_line_is_dropped_and_reported(tmp_path):
    path = tmp_path / "m.jsonl"
    _write(path, 5)
    text = path.read_text()
    path.write_text(text[: len(text) - 20])
    contents = read_log(path)
    assert contents.truncated
    assert [r["position"][0] for r in contents.records] == [0, 1, 2, 3]


def test_a_malformed_line_in_the_middle_is_an_input_error(tmp_path):
    path = tmp_path / "m.jsonl"
    _write(path, 3)
    lines = path.read_text().splitlines()
    lines[2] = lines[2][:10]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 3"):
        read_log(path)


def test_a_file_without_header_is_refused(tmp_path):
    path = tmp_path / "m.jsonl"
    path.write_text('{"kind": "odometry"}\n')
    with pytest.raises(InputError, match="no header"):
        read_log(path)
