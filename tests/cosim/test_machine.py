"""Machine descriptions: any axes, derived names, and one-line refusals naming the key."""

import pytest

from flexff.cosim.config_error import ConfigError
from flexff.cosim.machine import check_signals, load_machine, parse_machine

AXIS = {"name": "x", "measured": "plant.x", "feedforward": "pid.x_ff",
        "effort": "pid.x_effort", "range": [-0.05, 0.05], "velocity": 0.2, "acceleration": 2.0}


def machine(**axis_changes):
    return {"name": "drive", "axis": [{**AXIS, **axis_changes}]}


def test_an_axis_gets_its_reference_and_derived_names():
    drive = parse_machine(machine(unit="m", effort_unit="N"), "d.toml")
    x = drive.axis("x")
    assert (x.reference, x.derivatives, x.motion) == (
        "x_ref", ("vx_ref", "ax_ref", "jx_ref"), ("x", "vx", "ax"))
    assert drive.signals == ("x_ref", "vx_ref", "ax_ref", "jx_ref", "x_measured", "x_effort")
    assert (x.limits.low, x.limits.high, x.limits.jerk) == (-0.05, 0.05, None)
    assert drive.prior.terms == ("inertia", "viscous", "coulomb", "offset")
    assert drive.exact == {}
    assert parse_machine({**machine(), "exact": {"plant.encoder": 0}}, "d").exact == {
        "plant.encoder": 0.0}


def test_three_axes_with_a_kinematic_map_and_user_terms():
    axes = [{**AXIS, "name": n, "feedforward": f"c.{n}_ff", "effort": f"c.{n}_u"}
            for n in ("q1", "q2", "z")]
    axes[0]["measured"] = "0.5 * (enc.a + enc.b)"
    table = {"axis": axes, "prior": {"terms": ["inertia", "coulomb_asymmetric"],
                                     "extra": {"q1": {"gravity": "cos(q1) * aq2"}}}}
    three = parse_machine(table, "m.toml")
    assert [a.name for a in three.axes] == ["q1", "q2", "z"]
    assert three.axes[0].measured.names == {"enc.a", "enc.b"}
    assert three.prior.extra["q1"]["gravity"].names == {"q1", "aq2"}
    check_signals(three, ["enc.a", "enc.b", "plant.x", "c.q1_u", "c.q2_u", "c.z_u"],
                  ["c.q1_ff", "c.q2_ff", "c.z_ff"], "m.toml")


def test_a_description_from_its_own_file(tmp_path):
    (tmp_path / "drive.toml").write_text(
        '[machine]\nname = "drive"\n[[machine.axis]]\nname = "x"\nmeasured = "plant.x"\n'
        'feedforward = "pid.x_ff"\neffort = "pid.x_effort"\nrange = [-0.05, 0.05]\n'
        'velocity = 0.2\nacceleration = 2.0\n')
    assert parse_machine("drive.toml", "run.toml", tmp_path).axes[0].feedforward == "pid.x_ff"


@pytest.mark.parametrize("table, key", [
    (machine(range=[0.1, -0.1]), r"machine\.axis\[0\]\.range"),
    (machine(velocity=0), r"machine\.axis\[0\]\.velocity"),
    ({"axis": [{k: v for k, v in AXIS.items() if k != "acceleration"}]},
     r"machine\.axis\[0\]\.acceleration"),
    (machine(name="1x"), r"machine\.axis\[0\]\.name"),
    (machine(effort="x_effort"), r"machine\.axis\[0\]\.effort"),
    (machine(measured="plant.x +"), r"machine\.axis\[0\]\.measured"),
    (machine(speed=1.0), r"machine\.axis\[0\]\.speed"),
    ({"axis": []}, r"machine\.axis"),
    ({"axis": [AXIS, AXIS]}, r"machine\.axis\[1\]\.name"),
    ({"axis": [AXIS, {**AXIS, "name": "vx"}]}, r"machine\.axis\[\d\]\.name"),
    ({"axis": [AXIS], "prior": {"terms": ["mass"]}}, r"machine\.prior\.terms"),
    ({"axis": [AXIS], "prior": {"extra": {"x": {"g": "sin(y)"}}}},
     r"machine\.prior\.extra\.x\.g"),
    ({"axis": [AXIS], "prior": {"extra": {"y": {"g": "x"}}}}, r"machine\.prior\.extra\.y"),
    ({"axis": [AXIS], "exact": {"encoder": 0.0}}, r"machine\.exact\.encoder"),
    ({"axis": [AXIS], "exact": {"plant.encoder": "0"}}, r"machine\.exact\.plant\.encoder"),
    ({"axis": [AXIS], "exact": 0.0}, r"machine\.exact"),
])
def test_bad_descriptions_are_refused_naming_the_key(table, key):
    with pytest.raises(ConfigError, match=rf"^run\.toml: {key}: "):
        parse_machine(table, "run.toml")


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"machine: no such machine description file"):
        parse_machine("nowhere.toml", "run.toml", tmp_path)
    with pytest.raises(ConfigError, match=r"machine: no such machine description file"):
        load_machine(tmp_path / "nowhere.toml")


@pytest.mark.parametrize("outputs, inputs, key, words", [
    (["plant.xx", "pid.x_effort"], ["pid.x_ff"], "measured", "did you mean 'plant.xx'"),
    (["plant.x", "pid.x_effort"], ["pid.xff"], "feedforward", "not an input"),
    (["plant.x"], ["pid.x_ff"], "effort", "not an output"),
])
def test_signals_the_loop_lacks_are_refused(outputs, inputs, key, words):
    drive = parse_machine(machine(), "d.toml")
    with pytest.raises(ConfigError, match=rf"machine\.axis\[0\]\.{key}: .*{words}"):
        check_signals(drive, outputs, inputs, "d.toml")


def test_a_measured_position_is_no_effort():
    drive = parse_machine(machine(effort="plant.x"), "d.toml")
    with pytest.raises(ConfigError, match=r"effort: 'plant.x' is the measured position"):
        check_signals(drive, ["plant.x"], ["pid.x_ff"], "d.toml")
