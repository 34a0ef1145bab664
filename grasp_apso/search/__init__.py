"""The search: Guided Random Generation, APSO and the simple PSO, the final selection, and
the planner API (:func:`grasp_apso.search.planner.plan`)."""
