"""``python -m clusterfilter_ros.cli`` runs the ``clusterfilter`` command."""

import sys

from clusterfilter_ros.cli import main

sys.exit(main())
