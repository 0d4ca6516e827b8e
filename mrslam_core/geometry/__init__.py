"""Geometry: SE(2) poses, stereo triangulation."""
