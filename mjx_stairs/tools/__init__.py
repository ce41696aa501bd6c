"""Tools around a trained policy: play (video, MCAP for Foxglove) and export (ONNX)."""
