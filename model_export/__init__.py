"""torch -> ONNX export, parity checks and the ``models/manifest.json`` writer."""
