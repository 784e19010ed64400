"""Draw-free hypothesis designs for the single-image vanishing-point fit, against today's drawn RANSAC."""
