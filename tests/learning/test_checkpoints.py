"""Nothing a failed training can destroy: checkpoints, resuming (after kill -9 too) to the
weights of an uninterrupted run, a finished run refused without force and kept intact when
the retraining's final write fails (a full disk)."""

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

import flexff
import flexff.learning.train as training
from flexff.cli import main
from flexff.learning.export import export
from flexff.learning.run_folder import RunFolderError, load_run
from flexff.learning.synthetic import synthetic_dataset
from flexff.learning.train import train

FILES = ("run.json", "model.pt", "metrics.json", "loss.png")


@pytest.fixture(scope="module")
def uninterrupted(data, tmp_path_factory):
    """Three epochs of the fast LSTM, never interrupted."""
    out = tmp_path_factory.mktemp("runs") / "whole"
    metrics = train("lstm", "fast", data, out, progress=False, epochs=3)
    return out, metrics


@pytest.fixture(scope="module")
def other(data):
    """Another dataset of the same shape (other seed)."""
    return synthetic_dataset(data.parent / "other", n_train=4, n_test=1, duration=4.0,
                             rate_hz=200.0, seed=8)


def _weights(path):
    return load_run(path).network.state_dict()


def _same_weights(a, b):
    a, b = _weights(a), _weights(b)
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _stop_after(monkeypatch, epochs_done):
    """Interrupt training once the checkpoint after `epochs_done` epochs is written."""
    real = training.Checkpoints.epoch_done

    def stopping(self, epochs, network, optimizer, rng, history, *rest):
        real(self, epochs, network, optimizer, rng, history, *rest)
        if len(history["train"]) == epochs_done:
            raise KeyboardInterrupt

    monkeypatch.setattr(training.Checkpoints, "epoch_done", stopping)


def test_an_interrupted_run_resumes_to_the_same_weights(data, other, uninterrupted, tmp_path,
                                                        monkeypatch):
    whole, metrics = uninterrupted
    out = tmp_path / "run"
    _stop_after(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        train("lstm", "fast", data, out, progress=False, epochs=3, checkpoint_every=1)
    monkeypatch.undo()
    assert sorted(p.name for p in out.iterdir()) == ["best.pt", "checkpoint.pt"]
    best = torch.load(out / "best.pt", weights_only=True)
    assert best["val_mse"] == min(metrics["history"]["val"][:2]) and best["epoch"] in (1, 2)
    with pytest.raises(RunFolderError, match=r"unfinished training run \(checkpoint after epoch 2 "
                                             r"of 3\).*--resume.*--force"):
        train("lstm", "fast", data, out, progress=False, epochs=3, resume=False, force=False)
    with pytest.raises(RunFolderError, match="other settings \\(epochs: 3 there, 4 here\\)"):
        train("lstm", "fast", data, out, progress=False, epochs=4, resume=True)
    with pytest.raises(RunFolderError, match="other settings \\(the dataset differs"):
        train("lstm", "fast", other, out, progress=False, epochs=3, resume=True)
    resumed = train("lstm", "fast", data, out, progress=False, epochs=3, resume=True,
                    force=False)
    assert resumed["history"] == metrics["history"] | {"seconds": resumed["history"]["seconds"]}
    assert _same_weights(out, whole)
    assert sorted(p.name for p in out.iterdir()) == sorted(FILES)  # checkpoints gone


def test_a_finished_or_foreign_folder_needs_force(data, uninterrupted, tmp_path, capsys):
    whole, _ = uninterrupted
    before = {name: (whole / name).stat().st_mtime_ns for name in FILES}
    with pytest.raises(RunFolderError, match=r"holds a finished training run.*--force"):
        train("lstm", "fast", data, whole, progress=False, epochs=1, force=False)
    assert main(["train", "--model", "lstm", "--data", str(data), "-o", str(whole)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds a finished training run" in err and "--force" in err
    assert {name: (whole / name).stat().st_mtime_ns for name in FILES} == before
    with pytest.raises(RunFolderError, match=r"holds no checkpoint.pt to resume"):
        train("lstm", "fast", data, whole, progress=False, epochs=3, resume=True)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(RunFolderError, match=r"is not empty \(notes.txt\).*--force"):
        train("lstm", "fast", data, tmp_path, progress=False, epochs=1, force=False)
    with pytest.raises(ValueError, match="checkpoint_every must be at least 1"):
        train("lstm", "fast", data, tmp_path / "new", progress=False, checkpoint_every=0)


@pytest.mark.parametrize("failing", ["model.pt", "loss.png"])
def test_a_failed_final_write_keeps_the_finished_run(data, uninterrupted, tmp_path, monkeypatch,
                                                     failing):
    """A full disk while the retraining writes its run: the old run's files are untouched and
    load and export; the retraining's last checkpoint finishes it once there is space."""
    out = tmp_path / "run"
    out.mkdir()
    for name in FILES:
        (out / name).write_bytes((uninterrupted[0] / name).read_bytes())
    before = {name: (out / name).read_bytes() for name in FILES}

    def full_disk(path):
        with open(path, "wb") as handle:
            handle.write(b"\0" * 1000)  # half a file, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    if failing == "model.pt":
        real_save = torch.save
        monkeypatch.setattr(torch, "save", lambda obj, path: full_disk(path)
                            if os.path.basename(path) == "model.pt" else real_save(obj, path))
    else:
        monkeypatch.setattr(training, "plot_losses", lambda history, path, title: full_disk(path))
    with pytest.raises(OSError, match="No space left"):
        train("lstm", "fast", data, out, progress=False, epochs=2)
    monkeypatch.undo()
    assert {name: (out / name).read_bytes() for name in FILES} == before
    assert sorted(p.name for p in out.iterdir()) == sorted((*FILES, "best.pt", "checkpoint.pt"))
    assert load_run(out).config.epochs == 3
    export(out, tmp_path / "model.onnx")
    resumed = train("lstm", "fast", data, out, progress=False, epochs=2, resume=True)
    assert len(resumed["history"]["train"]) == 2 and load_run(out).config.epochs == 2
    assert sorted(p.name for p in out.iterdir()) == sorted(FILES)


# the child of the kill test: `flexff train` with the checkpoint writer of the module the CLI
# really runs (flexff.learning.train) wrapped so that, once its first checkpoint is on disk, it
# says so in a file and then waits there until it is killed
_HELD_CHILD = """
import sys, time
from pathlib import Path
import flexff.learning.train as training
from flexff.cli import main
held, args = Path(sys.argv[1]), sys.argv[2:]
real = training.Checkpoints.epoch_done
def held_after_the_first(self, epochs, network, optimizer, rng, history, *rest):
    real(self, epochs, network, optimizer, rng, history, *rest)
    if len(history["train"]) == 1:
        held.write_text("held")
        time.sleep(600)
training.Checkpoints.epoch_done = held_after_the_first
sys.exit(main(args))
"""


def test_training_killed_after_its_first_checkpoint_resumes(data, uninterrupted, tmp_path):
    """kill -9 of `flexff train` (held after its first checkpoint, so the kill lands mid-run);
    `flexff train --resume` then ends with three epochs and the uninterrupted run's weights."""
    out, held = tmp_path / "run", tmp_path / "held"
    args = ["train", "--model", "lstm", "--data", str(data), "-o", str(out), "--epochs", "3",
            "--checkpoint-every", "1"]
    # the child imports the flexff this test imports, from whatever folder pytest started in
    root = str(Path(flexff.__file__).resolve().parents[1])
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(filter(None, (root, os.environ.get("PYTHONPATH"))))}
    process = subprocess.Popen([sys.executable, "-c", _HELD_CHILD, str(held), *args],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                               cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not held.exists():
            assert process.poll() is None, ("the child ended without being held after its "
                                            "first checkpoint: " + process.stderr.read().decode())
            assert time.monotonic() < deadline, "the child was not held within 60 s"
            time.sleep(0.01)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
        process.stderr.close()
    assert process.returncode == -signal.SIGKILL  # killed while held, not finished
    assert not (out / "run.json").exists()
    assert sorted(p.name for p in out.iterdir()) == ["best.pt", "checkpoint.pt"]
    assert torch.load(out / "checkpoint.pt", weights_only=True)["epoch"] == 1
    assert main([*args, "--resume"]) == 0
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["epochs"] == 3 and len(saved["history"]["train"]) == 3
    assert saved["history"]["val"] == uninterrupted[1]["history"]["val"]
    assert _same_weights(out, uninterrupted[0])
