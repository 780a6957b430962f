"""Occupancy grids, map_server map I/O, likelihood fields and ray casting."""

from gatmo.maps.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid

__all__ = ["FREE", "OCCUPIED", "UNKNOWN", "OccupancyGrid"]
