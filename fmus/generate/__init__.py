"""Model definition (``models/``) -> modelDescription.xml + C (:mod:`.codegen`) -> compiled,
packaged and validated ``.fmu`` (:mod:`.build`)."""

#: the ``generationTool`` of every FMU railfmu builds (its first word): how a run knows its own
#: FMUs without importing the generator (sympy)
GENERATOR = "railfmu"
