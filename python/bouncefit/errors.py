"""The exceptions bouncefit raises. Their message is the one the command line prints after
``error:`` (naming the file and field at fault)."""


class BouncefitError(Exception):
    """Any error bouncefit reports."""


class InvalidInputError(BouncefitError, ValueError):
    """Bad input: a wrong option, or a file whose content is wrong (its field is named)."""


class FileError(BouncefitError, OSError):
    """A file could not be read or written (missing, unreadable, not writable)."""


class BouncefitWarning(UserWarning):
    """Something worth telling that is not an error (the command line's ``warning:`` lines)."""
