/* Stair, FMI 2.0 co-simulation: the model in ../common/stair.h behind the FMI 2.0 wrapper. */
#include "../common/stair.h"
#include "../common/fmi2_cosim.c"
