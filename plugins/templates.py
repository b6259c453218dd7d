"""Built-in component templates: polynomial, with memory, with hysteresis, neural."""
from mcl import hookimpl
from mcl.hysteresis import HysteresisTemplate
from mcl.templates import MemoryTemplate, NeuralTemplate, PolynomialTemplate

_TERMS = {"type": "array", "minItems": 1, "items": {"type": "string", "minLength": 1}}
_POLY = {"type": "object", "additionalProperties": False, "properties": {
    "lhs": _TERMS, "rhs": _TERMS, "degree": {"type": "integer", "minimum": 1, "maximum": 9},
    "start": {"type": "array", "items": {"type": "number"}}, "prefix": {"type": "string", "pattern": "^[A-Za-z_]\\w*$"},
    "scales": {"type": "object", "additionalProperties": {"type": "number"}},
    "family": {"type": "string"}}}


@hookimpl
def mcl_templates():
    return [PolynomialTemplate, MemoryTemplate, HysteresisTemplate, NeuralTemplate]


@hookimpl
def mcl_option_schemas():
    return {"template": {
        "polynomial": _POLY,
        "memory": _POLY,
        "hysteresis": {"type": "object", "additionalProperties": False, "properties": {
            "rhs": _TERMS, "start": {"type": "array", "items": {"type": "number"}},
            "span": {"type": "number", "exclusiveMinimum": 0},
            "shape": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
            "prefix": {"type": "string", "pattern": "^[A-Za-z_]\\w*$"}, "family": {"type": "string"}}},
        "neural": {"type": "object", "additionalProperties": False, "properties": {
            "hidden": {"type": "integer", "minimum": 1, "maximum": 64},
            "start": {"type": "array", "items": {"type": "number"}},
            "seed": {"type": "integer"}, "x": {"enum": ["v", "dv"]}, "coupled": {"type": "boolean"}}},
    }}
