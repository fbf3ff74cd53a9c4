"""extract_archive: FMU and SSP archives unpacked within a bound, names checked, nothing left
behind on a refusal; and the commands that unpack archives refusing a bomb with exit code 2."""

import re
import struct
import tempfile
import zipfile
from pathlib import Path

import pytest

from flexff.cli import main
from flexff.fmu.archive import UNPACK_LIMIT, UNPACK_LIMIT_ENV, extract_archive, unpack_limit
from flexff.fmu.errors import InputError
from flexff.fmu.importer import FmuInstance, read_fmu
from flexff.fmu.validation import validate_fmu
from tests.helpers import REFERENCE_FMUS

MiB = 1 << 20


@pytest.fixture
def temporary(tmp_path, monkeypatch) -> Path:
    """A temporary folder of its own for the test, so that what is left in it can be seen."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def bomb(path: Path, size: int = 8 * MiB, prefix: str = "resources/") -> Path:
    """A valid FMU (Dahlquist, FMI 2.0) with a member of `size` zero bytes: a few kB packed."""
    with zipfile.ZipFile(REFERENCE_FMUS / "fmi2" / "Dahlquist.fmu") as src, \
            zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            dst.writestr(item, src.read(item))
        dst.writestr(f"{prefix}zeros.bin", bytes(size))
    return path


def test_an_archive_within_the_bound_unpacks_whole(tmp_path):
    fmu = REFERENCE_FMUS / "fmi2" / "VanDerPol.fmu"
    folder = extract_archive(fmu, tmp_path / "out")
    with zipfile.ZipFile(fmu) as zf:
        files = {i.filename for i in zf.infolist() if not i.is_dir()}
        assert {p.relative_to(folder).as_posix() for p in folder.rglob("*")
                if p.is_file()} == files
        assert all((folder / name).read_bytes() == zf.read(name) for name in files)


def test_a_bomb_is_refused_and_nothing_is_left(tmp_path, temporary, monkeypatch):
    path = bomb(tmp_path / "bomb.fmu")
    assert path.stat().st_size < 100_000
    monkeypatch.setenv(UNPACK_LIMIT_ENV, "4M")
    with pytest.raises(InputError, match=rf"{path}: member 'resources/zeros.bin' takes the "
                                         rf"declared unpacked size past 4194304 bytes"):
        extract_archive(path)
    assert list(temporary.iterdir()) == []
    target = tmp_path / "given"
    with pytest.raises(InputError):
        extract_archive(path, target)
    assert not target.exists()
    monkeypatch.setenv(UNPACK_LIMIT_ENV, "16M")  # the bound raised: the same file unpacks
    assert (extract_archive(path, target) / "resources" / "zeros.bin").stat().st_size == 8 * MiB


def test_a_member_larger_than_it_declares_is_refused(tmp_path, temporary):
    """The central directory says 1000 bytes, the data inflates to 8 MiB."""
    path = bomb(tmp_path / "liar.fmu")
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        item = zf.getinfo("resources/zeros.bin")
    central = data.rindex(b"resources/zeros.bin") - 46  # its central directory record
    struct.pack_into("<I", data, central + 24, 1000)  # uncompressed size, central directory
    struct.pack_into("<I", data, item.header_offset + 22, 1000)  # ... and local header
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"member 'resources/zeros.bin' is damaged"):
        extract_archive(path)
    assert list(temporary.iterdir()) == []


@pytest.mark.parametrize("name", ["../evil.txt", "/etc/evil.txt", "a/../../evil.txt",
                                  "C:/evil.txt", "..\\evil.txt"])
def test_a_member_outside_the_folder_is_refused(tmp_path, temporary, name):
    path = tmp_path / "traversal.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")
        zf.writestr(name, "gotcha")
    with pytest.raises(InputError, match=re.escape(f"member {name!r} points outside the folder")):
        extract_archive(path, tmp_path / "out")
    assert not (tmp_path / "out").exists() and list(temporary.iterdir()) == []
    assert not (tmp_path / "evil.txt").exists()


def test_a_symbolic_link_is_refused(tmp_path):
    path = tmp_path / "link.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        item = zipfile.ZipInfo("resources/passwd")
        item.external_attr = (0o120777 << 16)
        zf.writestr(item, "/etc/passwd")
    with pytest.raises(InputError, match="is a symbolic link"):
        extract_archive(path, tmp_path / "out")


@pytest.mark.parametrize(("text", "limit"), [("", UNPACK_LIMIT), ("2048", 2048), ("3K", 3072),
                                             ("1.5G", 3 << 29), ("8MiB", 8 * MiB)])
def test_the_bound_reads_the_environment(monkeypatch, text, limit):
    monkeypatch.setenv(UNPACK_LIMIT_ENV, text)
    assert unpack_limit() == limit


@pytest.mark.parametrize("text", ["lots", "-1", "0", "4T"])
def test_a_bad_bound_is_an_input_error(monkeypatch, text):
    monkeypatch.setenv(UNPACK_LIMIT_ENV, text)
    with pytest.raises(InputError, match=UNPACK_LIMIT_ENV):
        unpack_limit()


def test_loading_a_bomb_fmu_is_refused(tmp_path, temporary, monkeypatch):
    path = bomb(tmp_path / "bomb.fmu")
    monkeypatch.setenv(UNPACK_LIMIT_ENV, "1M")
    with pytest.raises(InputError, match=r"zeros\.bin"):
        FmuInstance(read_fmu(path), "bomb")
    assert list(temporary.iterdir()) == []


def test_the_cli_refuses_a_bomb_with_exit_2(tmp_path, temporary, monkeypatch, capsys):
    """A run of an FMU and of an SSP archive holding a bomb."""
    fmu = bomb(tmp_path / "bomb.fmu")
    config = tmp_path / "run.toml"
    config.write_text(f'[run]\nstep = 0.1\nstop = 1.0\n[fmu.d]\npath = "{fmu}"\n')
    ssp = tmp_path / "system.ssp"
    with zipfile.ZipFile(ssp, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", "<x/>")
        zf.writestr("resources/zeros.bin", bytes(8 * MiB))
    monkeypatch.setenv(UNPACK_LIMIT_ENV, "1M")
    monkeypatch.setenv("FLEXFF_CACHE", str(tmp_path / "cache"))
    for target in (config, ssp):
        assert main(["run", str(target), "-o", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert "member 'resources/zeros.bin'" in err and "Traceback" not in err, err
    assert list(temporary.iterdir()) == []
    assert [p for p in (tmp_path / "cache").rglob("*") if p.is_file()] == []


def test_unpacked_folders_are_removed_after_use(temporary):
    with FmuInstance(read_fmu(REFERENCE_FMUS / "fmi3" / "VanDerPol.fmu"), "v"):
        assert len(list(temporary.iterdir())) == 1
    assert list(temporary.iterdir()) == []


def test_validation_unpacks_within_the_bound_of_the_moment(tmp_path, monkeypatch):
    """The checks run in a child forked from a server started earlier: the bound set after
    that still holds there."""
    path = bomb(tmp_path / "bomb.fmu")
    assert validate_fmu(path) == []  # the fork server runs from here on
    monkeypatch.setenv(UNPACK_LIMIT_ENV, "1M")
    [problem] = validate_fmu(path)
    assert "running the FMU failed" in problem and "'resources/zeros.bin'" in problem
