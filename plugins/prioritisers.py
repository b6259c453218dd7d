"""Built-in prioritisers for backward elimination: all at once, highest degree first."""
from mcl import hookimpl
from mcl.sparsify import AllAtOnce, HighestDegreeFirst


@hookimpl
def mcl_prioritisers():
    return [HighestDegreeFirst, AllAtOnce]
