"""The conformance cases, one module per area of the spec.  :func:`manip.conformance.suite.case.load_cases`
imports every module here; a module declares its cases with :func:`manip.conformance.suite.case.case`."""
