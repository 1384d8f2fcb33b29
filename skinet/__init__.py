"""SkiNet Live: predictive runtime verification of skill-based robots.

The ``skinet`` package is the pure core (no I/O outside its file layer, :mod:`skinet.files`):
skillset language (:mod:`skinet.lang`), Petri nets (:mod:`skinet.net`), safety
properties (:mod:`skinet.props`) and verification (:mod:`skinet.verify`).
"""

__version__ = "0.1.0"
