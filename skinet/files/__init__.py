"""The core's file layer: safe reading (:mod:`skinet.files.read`), TOML texts with positions
(:mod:`skinet.files.toml`) and the ``skinet`` a printed hint names (:mod:`skinet.files.program`)."""
