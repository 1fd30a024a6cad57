import type { TabProps } from '../../../fleet/contract';
import { useStoreSelect } from '../../../fleet/react';
import type { DuetSession } from '../session';
import { Thumbnail } from './common';

/** On the fleet tile: the thumbnail of the job being printed. */
export function TileExtra({ session }: TabProps<DuetSession>) {
  const file = useStoreSelect(session.store, (s) => s.model?.job.file ?? null);
  const thumb = file?.fileName ? (file.thumbnails.find((t) => t.data) ?? null) : null;
  if (!thumb) return null;
  return <Thumbnail thumb={thumb} size={56} alt="job thumbnail" />;
}
