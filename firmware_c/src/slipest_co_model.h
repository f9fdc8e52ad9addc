/* The CANopen node's model lifecycle (slipest_co_model.c): emergencies and the error register, what a
 * failed store call answers, and the model commands. A leaf of the node: it calls no other slipest_co
 * file, so every other one may include this header (library-internal, not public). */
#ifndef SLIPEST_CO_MODEL_H
#define SLIPEST_CO_MODEL_H

#include <stdint.h>

#include "slipest_co.h"

/* Error register bits (0x1001): the EMCY producer sets them, so they live with it */
#define SLIPEST_CO_ERR_GENERIC 0x01u
#define SLIPEST_CO_ERR_COMM 0x10u
#define SLIPEST_CO_ERR_MANUFACTURER 0x80u

/* Write an EMCY frame (unless stopped) and set the error register bits; returns 0 or 1. */
int slipest_co_emcy(slipest_co_t *co, uint16_t code, uint8_t reg_bits, int status, slipest_frame_t *out);

/* SDO abort code of a failed store call; an EMCY for a refused image or an NVM error. */
uint32_t slipest_co_store_failed(slipest_co_t *co, int status, slipest_frame_t *out, int *n);

/* 0x2002 rollback (`what` SLIPEST_CO_CMD_ROLLBACK; the object write checked that 1 was written) or, with 0, the
 * activation on trial of 0x1F51 "start"; may write one EMCY to *out (count in *n). Returns 0 or an SDO abort code. */
uint32_t slipest_co_model_command(slipest_co_t *co, unsigned what, slipest_frame_t *out, int *n);

/* 0x1F51 restart requests (slipest_co_t.restart), carried out by the NMT layer after the SDO answer */
#define SLIPEST_CO_RESTART_START 1u /* "start": boot-up, PRE-OPERATIONAL, the (new) model runs */
#define SLIPEST_CO_RESTART_RESET 2u /* "reset": the store re-read from NVM (an unconfirmed trial reverts), boot-up */

/* 0x1F51 sub 1 write (CiA 302-3 program control): stop, start (the downloaded model on trial), reset, clear, confirm
 * (0x80). Only in PRE-OPERATIONAL (else 0x08000022); an unknown command aborts 0x06090030. May write one EMCY to
 * *out (count in *n). Returns 0 or an SDO abort code. */
uint32_t slipest_co_program_control(slipest_co_t *co, uint32_t cmd, slipest_frame_t *out, int *n);

#endif
