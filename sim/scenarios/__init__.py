"""The shipped scenario files (package data: ``sensornet scenario`` lists them)."""
