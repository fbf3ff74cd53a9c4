"""The repository's copy of the Modelica Reference-FMUs is the one its README describes: every
file listed in SHA256SUMS with its hash, the license beside them, nothing unlisted."""

import hashlib

from tests.helpers import REFERENCE_FMUS


def test_reference_fmus_match_their_hashes():
    listed = dict(reversed(line.split("  ")) for line in
                  (REFERENCE_FMUS / "SHA256SUMS").read_text().splitlines())
    present = sorted(path.relative_to(REFERENCE_FMUS).as_posix()
                     for path in REFERENCE_FMUS.rglob("*.fmu"))
    assert present == sorted(listed) and len(present) == 6
    for name, digest in listed.items():
        assert hashlib.sha256((REFERENCE_FMUS / name).read_bytes()).hexdigest() == digest, name
    assert "2-Clause BSD" in (REFERENCE_FMUS / "LICENSE.txt").read_text()
