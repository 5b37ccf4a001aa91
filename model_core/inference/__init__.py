"""Running a released model: the NumPy and torch engines and the step generators they yield."""
