"""Team control (seed 003 Sec. II-III): group-state flooding with the vote of confidence, team tasks,
distributed allocation, the switchboard and the interface hierarchy."""
