"""sensornet package."""
