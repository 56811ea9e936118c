"""COCO instance annotations: run-length encoded masks and the dataset's JSON.

Masks are stored as COCO's compressed RLE (``{"size": [h, w], "counts": str}``), the
encoding ``pycocotools.mask.encode`` writes: run lengths over the image in
column-major order, starting with a run of zeros, each run written as the
difference from the run two before in 5-bit groups offset by 48 (``maskApi.c``,
``rleToString``). Boxes are COCO's ``[x, y, width, height]`` with pixel corners at
integers: a mask whose pixels span columns ``c0..c1`` has ``x = c0`` and
``width = c1 - c0 + 1``.
"""

import numpy as np


def rle_counts(crop: np.ndarray, top: int, left: int, height: int, width: int) -> list[int]:
    """Column-major run lengths (zeros first) of a mask over an image ``height x
    width`` that is False outside ``crop``, a (rows, cols) bool array whose top-left
    pixel is (``top``, ``left``) of the image."""
    crop = np.asarray(crop, dtype=bool)
    rows = crop.shape[0]
    padded = np.zeros((crop.shape[1], rows + 2), dtype=np.int8)  # one column a row
    padded[:, 1:-1] = crop.T
    col, row = np.nonzero(np.diff(padded, axis=1))  # run starts and ends, column by column
    index = (left + col) * height + top + row  # in the image's column-major order
    # a run ending at the bottom of one column and going on at the top of the next
    joined = np.flatnonzero(index[1:-1:2] == index[2::2])
    keep = np.ones(index.size, dtype=bool)
    keep[2 * joined + 1] = False
    keep[2 * joined + 2] = False
    edges = np.concatenate([[0], index[keep], [height * width]])
    counts = np.diff(edges).tolist()
    if len(counts) > 1 and counts[-1] == 0:  # a mask that ends on the last pixel
        counts.pop()
    return counts


def rle_string(counts: list[int]) -> str:
    """COCO's compressed text of run lengths (``pycocotools`` ``rleToString``)."""
    out = []
    for i, count in enumerate(counts):
        x = count - counts[i - 2] if i > 2 else count
        more = True
        while more:
            c = x & 0x1F
            x >>= 5  # arithmetic shift, as in C on a signed long
            more = x != -1 if c & 0x10 else x != 0
            if more:
                c |= 0x20
            out.append(chr(c + 48))
    return "".join(out)


def coco_bbox(visible_box) -> list[int]:
    """COCO ``[x, y, width, height]`` of an inclusive ``[left, top, right, bottom]``."""
    left, top, right, bottom = (int(v) for v in visible_box)
    return [left, top, right - left + 1, bottom - top + 1]
