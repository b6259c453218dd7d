"""Built-in component templates: polynomial, with memory, neural."""
from pipeline import hookimpl
from pipeline.templates import MemoryTemplate, NeuralTemplate, PolynomialTemplate


@hookimpl
def mcl_templates():
    return [PolynomialTemplate, MemoryTemplate, NeuralTemplate]
