from .cli import main
from .cli.output import leave

leave(main())
