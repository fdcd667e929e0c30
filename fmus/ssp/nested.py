"""Nested systems and system-level connectors of an SSD, made flat.

SSP lets a system hold systems; each system's connectors are ports that connections inside and
outside it join (a connection with no, or an empty, ``startElement``/``endElement`` names a
connector of the system that holds it). :func:`flatten` moves every component of a nested
system ``sub`` into the top-level system as ``sub.component`` (``sub.inner.component`` deeper
down), its connections with their ends renamed the same way (the nested system's own connector
``c`` becomes element ``sub``, connector ``c``), and its parameter bindings with the prefix
``sub.`` ahead of the top level's (an outer binding wins, as SSP orders them). What remains are
ports (:class:`Port`): the reader (``_Reader._connections``) follows each component input back
through ports to the output that feeds it, or to a port that nothing feeds: a connector of the
top-level system (an input or a parameter of the whole system, e.g. OMSimulator's
``Input_cref``) or of a nested one, whose value is a parameter of the run, bound by name
(``Input_cref``, ``sub.c``) and set on every input it reaches.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from railfmu.models.errors import UserError
from railfmu.fmus.ssp.xmltools import NS, children, local

ENDS = (("startElement", "startConnector"), ("endElement", "endConnector"))


@dataclass
class Port:
    element: str  # "" (the top-level system) or the nested system's path ("sub", "sub.inner")
    connector: str
    kind: str
    line: int

    @property
    def name(self) -> str:
        """How a binding, a variant or ``--set`` names it: ``c`` or ``sub.c``."""
        return f"{self.element}.{self.connector}" if self.element else self.connector


@dataclass
class Flat:
    ports: dict[tuple[str, str], Port] = field(default_factory=dict)
    systems: list = field(default_factory=list)  # the nested ssd:System elements, outermost first


def flatten(system, shown: str) -> Flat:
    """Flatten ``system`` (the top-level ssd:System element) in place; see the module."""
    flat = Flat()
    for c in system.iterfind("ssd:Connectors/ssd:Connector", NS):
        flat.ports[("", c.get("name"))] = Port("", c.get("name"), c.get("kind", ""), c.sourceline)
    for k in system.iterfind("ssd:Connections/ssd:Connection", NS):
        for e, _ in ENDS:
            if k.get(e) == "":  # OMSimulator writes the system's own connector as element ""
                del k.attrib[e]
    elements = system.find("ssd:Elements", NS)
    for sub in [el for el in children(elements) if local(el) == "System"] if elements is not None else []:
        flat.systems.append(sub)
        for key, port in _lift(system, sub, shown, flat).items():
            flat.ports[key] = port
    return flat


def _lift(parent, sub, shown: str, flat: Flat) -> dict[tuple[str, str], Port]:
    """Move the nested system ``sub`` (flattened first) into ``parent``; returns its ports,
    named as ``parent`` sees them."""
    name = sub.get("name")
    if not name or "." in name:
        raise UserError(f"{shown}:{sub.sourceline}: System {name!r}: a nested system needs a name without '.'")
    ports: dict[tuple[str, str], Port] = {}
    for c in sub.iterfind("ssd:Connectors/ssd:Connector", NS):
        ports[(name, c.get("name"))] = Port(name, c.get("name"), c.get("kind", ""), c.sourceline)
    elements = sub.find("ssd:Elements", NS)
    for inner in [el for el in children(elements) if local(el) == "System"] if elements is not None else []:
        flat.systems.append(inner)
        for (element, connector), port in _lift(sub, inner, shown, flat).items():
            port.element = f"{name}.{element}"
            ports[(port.element, connector)] = port
    for k in sub.iterfind("ssd:Connections/ssd:Connection", NS):
        for e, _ in ENDS:
            k.set(e, f"{name}.{k.get(e)}" if k.get(e) else name)
    for el in children(elements) if elements is not None else []:
        if local(el) == "Component":
            el.set("name", f"{name}.{el.get('name')}")
        elif local(el) == "SignalDictionaryReference":
            raise UserError(f"{shown}:{el.sourceline}: SignalDictionaryReference {el.get('name')!r} is not supported")
    for b in sub.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        b.set("prefix", f"{name}.{b.get('prefix', '')}")

    # move: components where the system was, connections and bindings to the parent's lists
    p_elements = parent.find("ssd:Elements", NS)
    at = list(p_elements).index(sub)
    for i, el in enumerate([el for el in children(elements) if local(el) == "Component"] if elements is not None else []):
        p_elements.insert(at + 1 + i, el)
    p_elements.remove(sub)
    moved = list(sub.iterfind("ssd:Connections/ssd:Connection", NS))
    if moved:
        _child(parent, "Connections", after=("Connectors", "ParameterBindings", "Elements")).extend(moved)
    bindings = list(sub.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS))
    if bindings:
        own = _child(parent, "ParameterBindings", after=("Connectors",))
        for i, b in enumerate(bindings):  # ahead of the parent's own: an outer binding wins
            own.insert(i, b)
    return ports


def _child(parent, tag: str, after: tuple[str, ...]):
    """``parent``'s ssd:<tag>, created in its schema place (after the ``after`` siblings) if absent."""
    el = parent.find(f"ssd:{tag}", NS)
    if el is None:
        el = parent.makeelement(f"{{{NS['ssd']}}}{tag}")
        last = max((i for i, c in enumerate(parent) if isinstance(c.tag, str) and local(c) in after), default=-1)
        parent.insert(last + 1, el)
    return el
