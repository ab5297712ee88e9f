"""The served face's OPC UA address space, modelled on OPC 40561 (OPC UA for Mining, Longwall Operation) as far as
it is public: a Longwall object holding the Shearer, the RoofSupportSystem with one object per shield, and the
FaceAlignmentSystem (use case 4.2.6). Browse names are readable by a person (`ShearerPosition`,
`Shield042/RamStroke`), in the namespace NAMESPACE. Units: SI (m, m/s, MPa for pressures, as the twin's truth).

Shearer: ShearerPosition (along the face from the headgate end of the pans [m], the haulage's arc length s),
PositionEast/North/Up (the body point in the tangent plane t [m]), Speed [m/s], Direction (+1 towards the tailgate,
-1 back, 0 standing), HaulageState (STOPPED, CUTTING, RETURN, SUMPING, CUT_OUT), Cycle, SimulationTime [s].

Each shield: RamStroke [m], RamPressure and LegPressure [MPa], Advance (from where it stood at the start [m]), Set
(canopy set against the roof), AppliedOffset (the offset its push applied on the current shear [m]).

FaceAlignmentSystem: Offsets (one per shield, positive towards the coal wall [m]) and SequenceNumber, written by an
external face alignment system: the roof support system applies a set on the next shear once its SequenceNumber
is new; AppliedSequenceNumber is the set in force and Status says what became of the last one written.
"""

from __future__ import annotations

from dataclasses import dataclass

from asyncua import Node, Server, ua

NAMESPACE = "urn:longwall-twin:opc40561"
"""The namespace of the twin's nodes."""

SHEARER_VARIABLES = {"ShearerPosition": 0.0, "PositionEast": 0.0, "PositionNorth": 0.0, "PositionUp": 0.0,
                     "Speed": 0.0, "Direction": 0, "HaulageState": "STOPPED", "Cycle": 0, "SimulationTime": 0.0}
SHIELD_VARIABLES = {"RamStroke": 0.0, "RamPressure": 0.0, "LegPressure": 0.0, "Advance": 0.0, "Set": True,
                    "AppliedOffset": 0.0}
HAULAGE_STATES = ("STOPPED", "CUTTING", "RETURN", "SUMPING", "CUT_OUT")
"""The truth's phase codes (twin.face.haulage) by name."""


def shield_name(k: int) -> str:
    """Shield k's browse name: Shield001 for the headgate's first."""
    return f"Shield{k + 1:03d}"


@dataclass
class FaceNodes:
    """The nodes the server writes and reads."""

    shearer: dict[str, Node]
    shields: list[dict[str, Node]]
    offsets: Node
    sequence: Node
    applied_sequence: Node
    status: Node


async def build(server: Server, n_shields: int) -> FaceNodes:
    """The Longwall object and everything under it (module docstring)."""
    ns = await server.register_namespace(NAMESPACE)
    longwall = await server.nodes.objects.add_object(ns, "Longwall")
    shearer_obj = await longwall.add_object(ns, "Shearer")
    shearer = {name: await shearer_obj.add_variable(ns, name, value) for name, value in SHEARER_VARIABLES.items()}
    rss = await longwall.add_object(ns, "RoofSupportSystem")
    shields = []
    for k in range(n_shields):
        obj = await rss.add_object(ns, shield_name(k))
        shields.append({name: await obj.add_variable(ns, name, value) for name, value in SHIELD_VARIABLES.items()})
    fas = await longwall.add_object(ns, "FaceAlignmentSystem")
    offsets = await fas.add_variable(ns, "Offsets", ua.Variant([0.0] * n_shields, ua.VariantType.Double))
    sequence = await fas.add_variable(ns, "SequenceNumber", ua.Variant(0, ua.VariantType.UInt32))
    applied = await fas.add_variable(ns, "AppliedSequenceNumber", ua.Variant(0, ua.VariantType.UInt32))
    status = await fas.add_variable(ns, "Status", "no offsets written yet")
    await offsets.set_writable()
    await sequence.set_writable()
    return FaceNodes(shearer, shields, offsets, sequence, applied, status)
