"""The motion-style REST service: FastAPI + onnxruntime, no torch.

Build the app with :func:`service.main.create_app`; run it with ``python -m service``.
"""
