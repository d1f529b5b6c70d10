"""``python -m drfkit.timing --profile quick|paper|path.yaml``: the inference benchmark's CLI
(``drfkit.timing.inference.main``)."""
import sys

from drfkit.timing.inference import main

sys.exit(main())
