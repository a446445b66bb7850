from models.util.array_util import *
from models.util.norm_util import *
from models.util.optim_util import *
from models.util.shell_util import *
