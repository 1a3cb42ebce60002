"""The project's shared vocabulary: modes, flags, payload codecs, port protocols and the
settings schema. A leaf: it imports no other package of the project."""
