/* Stair, FMI 3.0 co-simulation: the model in ../common/stair.h behind the FMI 3.0 wrapper. */
#include "../common/stair.h"
#include "../common/fmi3_cosim.c"
