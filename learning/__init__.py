"""Learning pipeline: data collection, preprocessing, models, training, ONNX export (to come)."""
