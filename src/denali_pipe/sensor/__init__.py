"""The TMF882x sensor, below the rig and the twin: how a zone turns photon arrivals into counts (`response`), the real captures it is fitted to (`captures`), and the fit (`fit`)."""
