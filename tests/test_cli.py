"""The command line, run as a user runs it."""

import json
import subprocess
import sys


def flexff(*args):
    return subprocess.run([sys.executable, "-m", "flexff", *args], capture_output=True, text=True)


def test_plant_info_json():
    result = flexff("plant", "info", "--variant", "hardware", "--json")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert info["variant"] == "hardware"
    assert len(info["natural_frequencies_hz"]) == 5
    units = {row["name"]: row["unit"] for row in info["parameters"]}
    assert units["k_t1"] == "N*m/A" and units["l_up"] == "m"


def test_plant_info_text():
    result = flexff("plant", "info")
    assert result.returncode == 0
    assert "1.7000 Hz" in result.stdout


def test_unknown_variant_is_a_clear_error():
    result = flexff("plant", "info", "--variant", "real")
    assert result.returncode == 2
    assert "invalid choice: 'real'" in result.stderr and "nominal" in result.stderr
