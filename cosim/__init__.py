"""Co-simulation: run configurations (TOML or SSP), their resolution into FMUs and wiring, the
fixed-step master over fmpy (FMI 2.0 and 3.0), recording, metrics, plots, the evaluation report,
batches, and the same runs under libcosim and through the engine alone in C (the floor). It
knows no machine: built-in FMUs, short forms and machine-specific reference kinds are registered
by machine packages (`builtins.register_builtin`, `plugins`, entry points `flexff.builtins`);
the manipulator's keys are documented in controllers.manipulator and controllers.short_form.

Public API: `config.load_config` / `parse_config` / `config_examples` / `expanded`,
`schema.RunConfig` (the configuration as data), `scenario.resolve`, `run.run_config`,
`ssp.export_ssp` / `load_ssp`, `batch.run_batch` / `sweep`, `master.Master` / `ResolvedFmu`,
`compare.compare_fmu` (one FMU in flexff and in FMPy),
`wiring.wire`, `recording.load_recording`, `metrics.run_metrics`, `report.write_report`,
`references` (reference trajectories), `builtins` / `plugins` / `checks` (what machine
packages register, and the checks their hooks share).
"""
