"""GATMO proper: the object map, absence, metaobjects, matching and relocation."""

from gatmo.objects.config import GatmoConfig
from gatmo.objects.mapper import Event, GatmoMapper
from gatmo.objects.objectmap import MapObject, ObjectMap

__all__ = ["Event", "GatmoConfig", "GatmoMapper", "MapObject", "ObjectMap"]
