/* Source, FMI 2.0 co-simulation: the model in ../common/source.h behind the FMI 2.0 wrapper. */
#include "../common/source.h"
#include "../common/fmi2_cosim.c"
