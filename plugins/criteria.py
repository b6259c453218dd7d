"""Built-in information criteria: BIC (extended for the choice among terms), AIC and AICc."""
from mcl import hookimpl
from mcl.stats import BUILTIN_CRITERIA


@hookimpl
def mcl_criteria():
    return list(BUILTIN_CRITERIA)
