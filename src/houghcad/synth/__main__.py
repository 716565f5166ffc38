"""``python -m houghcad.synth`` regenerates the bundled demo cloud (:func:`houghcad.synth.write_demo`)."""

from .parts import write_demo

if __name__ == "__main__":
    write_demo()
