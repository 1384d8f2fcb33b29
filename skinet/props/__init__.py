"""Safety properties and CTL formulas (docs/semantics.md §4, §6)."""

from skinet.props.formula import PlaceAtom, Property, Temporal, Until
from skinet.props.parser import parse_formula, parse_properties

__all__ = ["PlaceAtom", "Property", "Temporal", "Until", "parse_formula", "parse_properties"]
