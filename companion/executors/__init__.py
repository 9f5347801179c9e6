"""Platform-specific TST executors and the pure logic they use (seed 000 Sec. VI, Fig. 11-14).

``coverage``: the scan-ground executor's pattern generation (area polygon -> boustrophedon scan
lines and waypoints, sensor footprint, coverage check, scan specs); ``waypoint_order``: the
waypoint flags of Fig. 14a (any_order_flag, segment_flag, repeat_flag); ``inside_route``: shortest
transfers that stay inside a region.
"""
