"""The two built-in simulation engines: in-process CasADi and FMU (FMPy)."""
from mcl import hookimpl
from mcl.engine_casadi import CasadiEngine
from mcl.engine_fmu import FmuEngine


@hookimpl
def mcl_engines():
    return [CasadiEngine, FmuEngine]
