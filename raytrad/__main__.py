import sys

from raytrad.cli import main

sys.exit(main())
