"""The Identifying Extended Kalman Filter and its variants: the compiled pass, the rinsing loop, the data start, the spline, scheduled and grey-box filters."""
