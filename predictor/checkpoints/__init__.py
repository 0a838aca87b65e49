"""Packaged checkpoints (``<name>.safetensors``), loadable by name with ``predictor.load_predictor``."""
