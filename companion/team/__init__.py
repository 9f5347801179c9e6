"""Team control (seed 003 Sec. II-III): group-state flooding with the vote of confidence, team tasks,
distributed allocation, the switchboard and the interface hierarchy.

A team task kind is one module of :mod:`companion.team.kinds` (its check and division, its cost, the route
the simulator flies and its tree), registered there. One decision step (:mod:`companion.team.decision`)
is run by the flying member (:mod:`companion.team.member`) and by the simulator (:mod:`companion.team.sim`).
"""
