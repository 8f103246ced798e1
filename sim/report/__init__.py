"""Drawing results: the plot helpers the studies and reports share, one run's figures
(``sensornet plot``) and a report's Markdown as one HTML page."""
