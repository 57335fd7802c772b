"""Inference on whole scans: the model as a detector function and windowed whole-hall detection.

``windows`` cuts a scan larger than a training room into overlapping windows and merges their
detections; ``detector`` runs a model on one window through the config's test pipeline.
"""
