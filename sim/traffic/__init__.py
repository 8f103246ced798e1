"""Real air traffic as the truth (issue 34): recorded OpenSky state vectors (``opensky``) and
sensors that scan them as real radars and ADS-B receivers do (``radar``)."""
