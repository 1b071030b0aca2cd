"""Stages 2 to 6 of a run: the participant behind each component, every check, one converter
per connection, the order members step in, and the frozen plan the master executes."""
