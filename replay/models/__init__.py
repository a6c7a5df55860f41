"""Concrete models over the protocol of :mod:`replay.model`."""
