"""The item classes' colours: one palette for the simulator, the markers, the viewer and the GIF.

A class named after a colour of the palette shows in it (``'red'`` is red); any other class
takes the palette colour at its index in the cell's classes; an unknown class is grey.

>>> class_colour('blue')
(0.15, 0.35, 0.9)
>>> class_colour('bolts', ('nuts', 'bolts'))
(0.15, 0.35, 0.9)
>>> class_colour_255('red')
(217, 38, 38)
"""
from typing import Sequence, Tuple

RGB = Tuple[float, float, float]

#: RGB (0-1) of the palette, in order; a class named like one of them shows in it
PALETTE = {'red': (0.85, 0.15, 0.15), 'blue': (0.15, 0.35, 0.9), 'green': (0.15, 0.7, 0.25),
           'yellow': (0.95, 0.8, 0.1)}
UNKNOWN: RGB = (0.5, 0.5, 0.5)


def class_colour(cls: str, classes: Sequence[str] = ()) -> RGB:
    """Return the RGB (0-1) of item class ``cls`` among the cell's ``classes``."""
    if cls in PALETTE:
        return PALETTE[cls]
    classes = list(classes)
    if cls not in classes:
        return UNKNOWN
    colours = list(PALETTE.values())
    return colours[classes.index(cls) % len(colours)]


def class_colour_255(cls: str, classes: Sequence[str] = ()) -> Tuple[int, int, int]:
    """Return :func:`class_colour` as 0-255 integers (web pages, images)."""
    r, g, b = class_colour(cls, classes)
    return round(r * 255), round(g * 255), round(b * 255)
