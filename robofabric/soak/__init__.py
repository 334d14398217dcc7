"""Soak testing: a class in the lab for hours under a seeded nemesis, its history, and a checker.

``history`` (the records), ``observer`` (the wire's half of the history), ``student`` (one student's
process), ``nemesis`` (the faults), ``procs`` (peers' resources from /proc), ``run`` (the soak) and
``checker`` (the invariants). ``robofabric bench soak`` runs it (robofabric/bench/soak.py); see
docs/benchmarks.md, "Soak".
"""
