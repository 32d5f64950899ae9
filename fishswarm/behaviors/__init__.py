"""What a fish decides: pure functions from a perception to a desired motion."""
