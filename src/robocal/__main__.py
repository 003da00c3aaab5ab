import sys

from robocal.cli.main import main

sys.exit(main())
