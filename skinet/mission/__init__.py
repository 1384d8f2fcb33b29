"""Mission scenarios, their replay on the core and the monitor log a replay makes."""
