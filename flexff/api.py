"""flexff from Python, for scripts and notebooks: the same validated run model and engine as the
command line (`flexff run`), as functions.

    from flexff import api

    config = api.load("run.toml")                # TOML or SSP, checked like `flexff run`
    recording = api.simulate(config)             # in memory: recording["vdp.x0"], .time
    metrics = api.run(config, "out")             # into a folder, as `flexff run ... -o out`
    configs = api.sweep("run.toml", {"fmu.vdp.parameters.mu": [0.5, 1.5]})
    results = api.run_many(configs, "sweep")     # in parallel, one subfolder each
    result = api.read("out")                     # flexff.results.load: recording, metrics, run.json
    api.register_builtin("gain", (api.Option("k", "number", 1.0),), gain_system)  # [fmu.g]

A configuration is a frozen cosim.schema.RunConfig; change one through `api.sweep` (or
dataclasses.replace and `api.check`), so that every change passes the checks a file passes.
"""

from __future__ import annotations

from flexff.cosim.batch import BatchResult, sweep
from flexff.cosim.batch import run_batch as run_many
from flexff.cosim.builtins import Option, register_builtin
from flexff.cosim.config import checked as check
from flexff.cosim.recording import Recording
from flexff.cosim.run import load_run_config as load
from flexff.cosim.run import run_config as run
from flexff.cosim.run import simulate_config as simulate
from flexff.cosim.schema import RunConfig
from flexff.results import RunResult
from flexff.results import load as read

__all__ = ["BatchResult", "Option", "Recording", "RunConfig", "RunResult", "check", "load",
           "read", "register_builtin", "run", "run_many", "simulate", "sweep"]
