"""Coordinated multi-robot frontier exploration on an occupancy grid (002 section V)."""
