"""Co-simulation: run configurations (TOML or SSP), their resolution into FMUs and wiring, the
fixed-step master over fmpy (FMI 2.0 and 3.0), recording, metrics, plots, batches, and the same
runs under libcosim and through the engine alone in C (the floor). It knows no machine: built-in
FMUs, short forms and reference kinds are registered by machine packages (`builtins`, `plugins`,
entry points `flexff.builtins`).

Public API: `config.load_config` / `parse_config` / `expanded` / `checked`,
`example_configs.config_examples`, `schema.RunConfig` (the configuration as data),
`scenario.resolve`, `run.run_config`, `ssp.export_ssp` / `load_ssp`, `batch.run_batch` /
`sweep`, `master.Master` / `ResolvedFmu`, `compare.compare_fmu` (one FMU in flexff and in
FMPy), `wiring.wire`, `recording.load_recording`, `metrics.run_metrics`, `references`
(reference trajectories), `builtins` / `plugins` / `checks` (what machine packages register).

Docs: "Architecture and one run's path" (docs/explanation/architecture.md) and "Run
configuration" (docs/reference/configuration.md).
"""
