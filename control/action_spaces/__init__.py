"""control.action_spaces."""
