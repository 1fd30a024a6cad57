import { z } from 'zod';

/**
 * A record of the alarm centre (gateway/alarms.ts keeps them; the page shows them): one alarm or
 * message of one machine, from when the controller raised it to when it cleared it, and who
 * acknowledged it when. The same schema checks the gateway's file and the page's answers.
 */
export const alarmRecordSchema = z.object({
  id: z.string().max(40),
  machine: z.string().max(100),
  machineName: z.string().max(200),
  family: z.string().max(40),
  /** The condition (the family's alarm id, `xtool-flame`); one open record per machine and key. */
  key: z.string().max(200),
  severity: z.enum(['critical', 'warning', 'info']),
  text: z.string().max(500),
  /** Blocks every page until a person acknowledges it (an xTool flame). */
  blocking: z.boolean().default(false),
  /** ms since epoch */
  since: z.number(),
  clearedAt: z.number().nullable(),
  ackBy: z.string().max(200).nullable(),
  ackAt: z.number().nullable(),
});

export type AlarmRecord = z.infer<typeof alarmRecordSchema>;
