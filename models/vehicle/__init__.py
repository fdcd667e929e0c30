"""Vehicle models: the wheelset + suspended frame (Muñoz et al., simplified model), the complete
lateral vehicle (Muñoz et al., complete model) and the vertical ERRI B176 coach (Onat et al. 2016)."""
