"""The physics that produces step problems: scenes, contacts, laws and assembly."""
from .contacts import Contacts, find_contacts
from .laws import Coulomb, GlueyCoulomb, GlueyLubrication, Inelastic, Law, PairState
from .scene import Grains, Planes, Scene, Schedule

__all__ = ["Contacts", "find_contacts", "Coulomb", "GlueyCoulomb", "GlueyLubrication",
           "Inelastic", "Law", "PairState", "Grains", "Planes", "Scene", "Schedule"]
