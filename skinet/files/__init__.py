"""The core's file layer: safe reading (:mod:`skinet.files.read`) and TOML texts with positions
(:mod:`skinet.files.toml`)."""
