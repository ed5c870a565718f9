"""Maps, obstacles and sensors."""
