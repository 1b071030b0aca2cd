/* Feedthrough, FMI 3.0 co-simulation: the model in ../common/feedthrough.h behind the FMI 3.0 wrapper. */
#include "../common/feedthrough.h"
#include "../common/fmi3_cosim.c"
