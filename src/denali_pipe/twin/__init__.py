"""The digital twin: the calibrated scene as a Mitsuba 3 / mitransient scene
and an analytic three-bounce model, rendered per (object, size) as every
zone's transient histogram (paper supplement section 11.4)."""
