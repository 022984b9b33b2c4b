"""Frictionless contact of DEM bodies (paper §3.4, §4): rigid obstacles (``RigidContact`` with
``HalfSpace`` obstacles) and contact between the bodies of a mesh (``PairContact``), both
following the protocol of ``protocol.ContactModel``."""

from dolfinx_dem.contact.pair import PairContact
from dolfinx_dem.contact.protocol import ContactModel
from dolfinx_dem.contact.rigid import HalfSpace, RigidContact

__all__ = ["ContactModel", "HalfSpace", "PairContact", "RigidContact"]
