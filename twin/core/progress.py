"""Progress bars for long work: shown on a terminal only, never in a log file or a
pipe (tqdm's ``disable=None``), and never when the command was asked for none."""

from tqdm import tqdm


def progress_bar(iterable=None, *, progress: bool = True, **options) -> tqdm:
    """A tqdm bar over ``iterable`` (or one updated by hand), drawn on stderr when
    ``progress`` is set and stderr is a terminal; ``options`` go to tqdm (``total``,
    ``desc``, ``unit``, ``leave``, ...)."""
    return tqdm(iterable, disable=None if progress else True, **options)
