"""Co-simulation master: run configurations, stepping, recording, metrics and plots (to come)."""
