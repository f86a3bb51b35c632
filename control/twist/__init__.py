"""control.twist."""
