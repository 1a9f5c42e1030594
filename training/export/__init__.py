"""ONNX export of the trained chain and its model card (docs/contracts.md §3): ``python -m training export``."""
