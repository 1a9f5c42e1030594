"""ONNX export of the trained chain and its model card (SPEC §3): ``python -m training export``."""
