"""The example run configurations shipped in cosim/examples/, as text: apart from cosim.config
so that `flexff config example` reads them without loading numpy or the FMU importer."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

EXAMPLE_PATH = re.compile(r'^(\s*path\s*=\s*)"([^"/][^"]*)"', re.MULTILINE)  # a relative path


def config_examples() -> dict[str, str]:
    """Example configurations (TOML text) by name, shipped in cosim/examples/.

    The files they name (third-party FMUs, CSV tables) ship beside them; their relative paths
    are made absolute, so an example saved anywhere runs from there.
    """
    folder = Path(str(resources.files("flexff.cosim") / "examples"))
    return {path.stem: EXAMPLE_PATH.sub(lambda m: f'{m[1]}"{(folder / m[2]).as_posix()}"',
                                        path.read_text())
            for path in sorted(folder.glob("*.toml"))}
