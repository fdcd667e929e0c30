"""Model definition (``models/``) -> modelDescription.xml + C (:mod:`.codegen`) -> compiled,
packaged and validated ``.fmu`` (:mod:`.build`)."""
