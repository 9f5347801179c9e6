"""Simulated sensors of the companion (seed 000 Sec. VI-E ``sensor_type``, Sec. VII).

``scenario``: the objects placed in the world (a YAML file); ``camera``: a downward camera process that
reports the objects in its footprint as beliefs and labels a scan's detections with its data_uuid.
"""
