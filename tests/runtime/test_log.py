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


def test_the_file_is_created_at_the_first_record_only(tmp_path):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    log.close()
    assert not path.exists()  # a run that wrote nothing leaves no file


def test_the_log_stops_at_its_size_limit_with_a_last_line_that_says_so(tmp_path):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path, max_bytes=20_000, keep_records=False)
    log.write({"kind": "header", "version": LOG_VERSION})
    for i in range(1000):
        log.write({"kind": "odometry", "t": 0.1 * i, "position": [i, 0.0]})
    log.close()
    assert log.records == []  # bounded in memory too
    size = path.stat().st_size
    assert 19_000 - 1024 < size <= 20_000
    lines = path.read_text().splitlines()
    last = json.loads(lines[-1])
    assert last["kind"] == "log stopped" and "size limit of 20000 bytes" in last["reason"]
    assert log.stopped == last["reason"]
    assert len(lines) - 1 + log.unwritten == 1001  # every record is in the file or counted
    contents = read_log(path)  # it still reads back, up to where it stopped
    assert not contents.truncated and contents.records[-1]["kind"] == "log stopped"


def test_a_failed_write_stops_the_log_without_raising(tmp_path, monkeypatch):
    import errno

    import hptrack.runtime.log as log_module

    class Full:
        def __init__(self):
            self.lines = 0

        def write(self, text):
            self.lines += 1
            if self.lines > 3:
                raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self):
            pass

        def close(self):
            raise OSError(errno.ENOSPC, "No space left on device")  # the buffered rest

    monkeypatch.setattr(log_module, "open", lambda *a, **k: Full(), raising=False)
    log = MissionLog(tmp_path / "m.jsonl")
    for i in range(10):
        record = log.write({"kind": "odometry", "t": float(i)})
    assert record["seq"] == 9 and len(log.records) == 10  # the records go on in memory
    assert log.stopped == "the write failed (No space left on device)"
    assert log.unwritten == 7
    log.close()


def test_a_log_whose_first_write_fails_leaves_no_empty_file(tmp_path, monkeypatch):
    import errno

    import hptrack.runtime.log as log_module

    class Full:
        def __init__(self, file):
            self.file = file

        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            self.file.close()

    monkeypatch.setattr(log_module, "open", lambda *a, **k: Full(open(*a, **k)), raising=False)
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    log.write({"kind": "header", "version": LOG_VERSION})
    assert log.stopped is not None and not path.exists()
