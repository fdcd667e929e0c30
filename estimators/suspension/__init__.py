"""Vehicle suspension (Onat et al. 2016): the secondary vertical stiffness of a coach from its
inertial signals."""
