"""Fault injection for reliability trials: a YAML specification and a deterministic stream filter.

``trial replay --faults FILE`` passes the bag's time-ordered ``(t_ns, topic, msg)`` stream through
:class:`FaultInjector` and stores :meth:`FaultInjector.summary` with the run, so the evaluation can
tell which solutions fall inside which fault window.
"""

from .inject import FaultError, FaultInjector, FaultRecord, inject
from .spec import KINDS, Fault, FaultSpec, FaultSpecError, load_fault_spec, parse_fault_spec

__all__ = ["KINDS", "Fault", "FaultError", "FaultInjector", "FaultRecord", "FaultSpec",
           "FaultSpecError", "inject", "load_fault_spec", "parse_fault_spec"]
