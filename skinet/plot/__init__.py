"""Pictures drawn with matplotlib (Agg canvas, no display); outside the pure core."""
