"""The digital twin: the calibrated scene as a Mitsuba 3 / mitransient scene
and an analytic three-bounce model, rendered per (object, size) as the
centre pixel's transient histogram (paper supplement section 11.4)."""
