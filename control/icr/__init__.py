"""control.icr."""
