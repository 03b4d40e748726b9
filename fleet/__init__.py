"""Constellations over hours to days: satellites, tasks, opportunities, passes, schedules and their checker."""
