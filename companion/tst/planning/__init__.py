"""Planning helpers of the scan-ground leaf (seed 000 Sec. VI-E, Fig. 14a): ``coverage`` (area polygon ->
boustrophedon scan lines and waypoints, coverage check, scan specs), ``waypoint_order`` (the waypoint
flags any_order_flag, segment_flag, repeat_flag) and ``inside_route`` (shortest transfers inside a region).
"""
