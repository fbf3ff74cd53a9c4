"""Co-simulation: run configurations (TOML), the fixed-step master over fmpy, recording,
metrics, plots, the evaluation report, batches, and the same runs under libcosim and as a
plain C loop.

Public API: `config.load_config` / `parse_config` / `config_examples`, `run.run_config`,
`batch.run_batch` / `sweep`, `master.Master` / `SlaveSpec`, `recording.load_recording`,
`metrics.run_metrics`, `report.write_report`, `references` (reference trajectories).
"""
