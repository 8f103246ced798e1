"""The shipped campaign files (package data: ``sensornet campaign NAME``)."""
