"""A run owns its output folder while it writes (cosim.folder_lock): a second run into it is
refused at once with one line naming the first one's pid, a record is joined from its own
writer's chunks only, and run.json says what the record holds."""

import json
import os

import numpy as np

from flexff.cli import main
from flexff.cosim.folder_lock import LOCK_NAME, folder_lock
from flexff.cosim.recording import PARTS_NAME, RecordWriter, load_recording
from tests.cosim.test_streaming import vdp_config


def test_a_second_run_into_a_folder_in_use_is_refused(tmp_path, capsys):
    (tmp_path / "run.toml").write_text(vdp_config(1.0))
    out = tmp_path / "out"
    out.mkdir()
    with folder_lock(out):  # another run's lock (flock: a second open file conflicts)
        code = main(["run", str(tmp_path / "run.toml"), "-o", str(out)])
        assert (out / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    err = capsys.readouterr().err
    assert code == 1
    assert err == (f"flexff: error: {out}: another flexff run (pid {os.getpid()}) is writing "
                   f"into this folder: wait for it to end, or give another output folder "
                   f"(-o)\n")
    assert sorted(p.name for p in out.iterdir()) == []  # nothing of the refused run's
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(out)]) == 0  # free again
    assert not (out / LOCK_NAME).exists()


def test_a_record_is_joined_from_its_own_chunks_only(tmp_path):
    writer = RecordWriter(tmp_path)
    for k0 in (0, 3):
        writer.write(np.arange(k0, k0 + 3.0), {"a": np.arange(k0, k0 + 3.0)})
    stranger = RecordWriter.__new__(RecordWriter)  # another writer's chunk in the same folder
    stranger.parts, stranger.count, stranger.points, stranger.times = writer.parts, 2, 0, None
    stranger.write(np.array([99.0]), {"a": np.array([99.0])})
    writer.close()
    assert load_recording(tmp_path).time.tolist() == [0, 1, 2, 3, 4, 5]
    assert not (tmp_path / PARTS_NAME).exists()


def test_run_json_says_what_the_record_holds(tmp_path):
    (tmp_path / "run.toml").write_text(vdp_config(2.0, "[record]\nevery = 3\n"))
    assert main(["run", str(tmp_path / "run.toml"), "-o", str(tmp_path)]) == 0
    recorded = json.loads((tmp_path / "run.json").read_text())["recorded"]
    time = load_recording(tmp_path).time
    assert recorded == {"points": time.size, "first_time": 0.0, "last_time": time[-1],
                        "every": 3, "complete": True}
    assert time.size == 667
