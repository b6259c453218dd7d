"""The two built-in simulation engines: in-process CasADi and FMU (FMPy)."""
from pipeline import hookimpl
from pipeline.engine_casadi import CasadiEngine
from pipeline.engine_fmu import FmuEngine


@hookimpl
def mcl_engines():
    return [CasadiEngine, FmuEngine]
