/* Faulty, FMI 2.0 co-simulation: the model in ../../common/faulty.h behind the FMI 2.0 wrapper. */
#include "../../common/faulty.h"
#include "../../common/fmi2_cosim.c"
