"""Learning pipeline: datasets, preprocessing, networks, training, ONNX export, ILC and the
evaluation.

Entry points, free of argument parsing so the CLI can call them: collect.collect,
train.train, export.export, evaluate.evaluate, ilc.ilc, dataset.load_dataset /
write_dataset, synthetic.synthetic_dataset.

Docs: "Learning" (docs/explanation/learning.md), "ILC and the noise floor"
(docs/explanation/ilc-noise-floor.md) and "File formats" (docs/reference/file-formats.md).
"""
