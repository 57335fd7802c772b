"""Namespace for mmdet3d-style plugin projects."""
