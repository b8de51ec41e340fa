"""PuzzleBot lab hardware driver: ROS-free core (ESP8266 protocol, ...)."""
