"""The two ways a bake stops early: bad input (BakeError, said before any long work) or a cancel."""


class BakeError(Exception):
    """Input the bake cannot use. The message names the object, file or setting at fault."""


class BakeCancelled(Exception):
    """The user asked to stop; nothing has been written."""
