"""Learning pipeline: datasets, preprocessing, networks, training and ONNX export.

Public entry points (kept free of argument parsing so the CLI can call them):
  learning.collect.collect(set_name, out, workers, scheduler) -> dataset folder (co-simulated)
  learning.train.train(model, preset, data, out, **overrides) -> metrics dict
  learning.export.export(run, out, inputs="features") -> path of the ONNX graph
  learning.evaluate.evaluate(env, out, preset, models) -> summary (Table 5.2 / 6.2 for flexff)
  learning.ilc.ilc(config, out, iterations) -> the ILC's record (e2 per trial; the force table)
  learning.dataset.load_dataset(path) / write_dataset(...)
  learning.synthetic.synthetic_dataset(path, ...)          random data without co-simulation
  learning.synthetic.synthetic_collection_set(path, "sim")  the collected set's references

Modules: dataset (the on-disk format), trajectories and collect (the co-simulated sets),
synthetic (data without co-simulation), features (signal processing; the 63 / 6 features
themselves are controllers.features),
scaling (min-max), casadi_torch and rigid (plant expressions in torch; the pgnn's rigid-body
prior), models (LSTM, CNN-LSTM, TCN), presets (thesis / fast), batches (validation windows,
TBPTT chunks, random windows), threads (CPU thread policy), train, workers (models trained
side by side, one process per core), run_folder, deploy (the
model in SI units), export (ONNX), ilc and ilc_filter (iterative learning control: the best
feedforward force for one reference, the evaluation's limit), evaluate (collect, train, export,
co-simulate, report).
"""
