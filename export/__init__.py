"""Export of a trained model: ONNX, fixed-point scheme and torch integer reference, C headers, test vectors."""
