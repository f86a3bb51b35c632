"""control.follow."""
