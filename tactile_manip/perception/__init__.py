"""Perception: reconstructors (ONNX model and interpolation baselines), image metrics, and pose."""
