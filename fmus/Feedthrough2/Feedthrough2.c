/* Feedthrough, FMI 2.0 co-simulation: the model in ../common/feedthrough.h behind the FMI 2.0 wrapper. */
#include "../common/feedthrough.h"
#include "../common/fmi2_cosim.c"
