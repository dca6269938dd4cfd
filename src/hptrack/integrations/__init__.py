"""Bridges from hptrack's planners to other frameworks.

* `hptrack.integrations.stonesoup`: a Stone Soup sensor manager that flies an actionable
  platform with any hptrack planner (needs the ``stonesoup`` extra).

Each bridge imports its framework itself, so importing this package needs none of them.
"""
