//! The iceoryx2 service type of every port: iceoryx2's `ipc` service with two differences. Its
//! global management segment (a node counter) is a file in the namespace's private root
//! directory instead of a POSIX shared-memory object in `/dev/shm`, and that file is owner-only:
//! iceoryx2 creates it and then makes it world-writable (0666, "global access"), and any local
//! user could open it in that moment and keep writing to it. [`OwnerOnlyFile`] is iceoryx2's file
//! storage with the global access switched off, so the file goes from write-only for its owner
//! (while being initialised) straight to 0600, and it lives in a 0700 directory besides. And its
//! in-process reference counting recycles its boxes ([`super::recycled`]): iceoryx2 creates one
//! per loaned sample, which would be a heap allocation per publish in the board's 1 kHz loop.
//! Every other resource is iceoryx2's own `ipc` one (owner-only shared memory in `/dev/shm`,
//! service and node files under the root directory), so clients of the plain `ipc` service
//! (iceoryx2's Python bindings) still talk to the same services.
//!
//! [`ThreadSafe`] is the same service with iceoryx2's mutex-protected reference counting instead
//! (ports that may be used from any thread): the bridge publishes from Zenoh's callbacks with it.

use core::fmt::Debug;
use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::time::Duration;
use iceoryx2::prelude::{FileName, Path};
use iceoryx2::service::ipc;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_memory::bump_allocator::BumpAllocator;
use iceoryx2_bb_posix::file::AccessMode;
use iceoryx2_cal::dynamic_storage::{
    DynamicStorage, DynamicStorageBuilder, DynamicStorageCreateError, DynamicStorageOpenError,
    DynamicStorageOpenOrCreateError,
};
use iceoryx2_cal::named_concept::{
    NamedConcept, NamedConceptBuilder, NamedConceptDoesExistError, NamedConceptListError,
    NamedConceptMgmt, NamedConceptPathHintRemoveError, NamedConceptRemoveError,
};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator as ShmBumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::*;

/// Both service types: iceoryx2's `ipc` resources with the owner-only global file; `$policy` is
/// the in-process reference counting of the ports' shared state (the only difference).
macro_rules! vic_service {
    ($(#[$doc:meta])* $name:ident, $policy:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone)]
        pub struct $name {}

        impl iceoryx2::service::Service for $name {
            type StaticStorage = <ipc::Service as iceoryx2::service::Service>::StaticStorage;
            type ConfigSerializer =
                <ipc::Service as iceoryx2::service::Service>::ConfigSerializer;
            /// The one change of resource: an owner-only file under `global.root_path` (the
            /// private directory).
            type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
                OwnerOnlyFile<T>;
            type Bag = bag::recommended::Recommended;
            type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
                dynamic_storage::recommended::Ipc<T>;
            type ServiceNameHasher = hash::recommended::Recommended;
            type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
            type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
            type Connection = zero_copy_connection::recommended::Ipc;
            type Event = event::recommended::Ipc;
            type Monitoring = monitoring::recommended::Ipc;
            type Reactor = reactor::recommended::Ipc;
            type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = $policy<T>;
            type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
                dynamic_storage::recommended::Ipc<KeyType>;
            type BlackboardPayload = shared_memory::recommended::Ipc<ShmBumpAllocator>;
            type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
        }

        impl iceoryx2::service::internal::ServiceInternal<$name> for $name {}
    };
}

use super::recycled::Recycled;
use iceoryx2_cal::arc_sync_policy::mutex_protected::MutexProtected;

vic_service!(
    /// iceoryx2's `ipc` service with its global management segment an owner-only file in the
    /// private root directory, and iceoryx2's single-threaded reference counting with its boxes
    /// recycled, so a publish takes no memory from the allocator (`super::recycled`). Its ports
    /// are neither `Send` nor `Sync`. Every daemon's service type.
    Service,
    Recycled
);

vic_service!(
    /// [`Service`]'s thread-safe sibling: the same resources (so its ports and [`Service`]'s
    /// talk to each other on one service, and the namespace's files and their modes are the
    /// same), with iceoryx2's `MutexProtected` policy (as `ipc_threadsafe`): its ports are `Send`
    /// and `Sync`, at the cost of a mutex per port operation and an allocation per loan. For
    /// the bridge's publishers, which run on Zenoh's threads; never in the board's 1 kHz loop.
    ThreadSafe,
    MutexProtected
);

type File<T> = dynamic_storage::file::Storage<T>;
type FileBuilder<'b, T> = dynamic_storage::file::Builder<'b, T>;

/// iceoryx2's file-backed dynamic storage that never grants global access: its files end 0600
/// whatever the caller asks for. Everything else is delegated unchanged.
#[derive(Debug)]
pub struct OwnerOnlyFile<T: Debug + Send + Sync + ZeroCopySend>(File<T>);

/// The builder of [`OwnerOnlyFile`]: iceoryx2's file builder with `enable_global_access` ignored.
#[derive(Debug)]
pub struct OwnerOnlyBuilder<'b, T: Debug + Send + Sync + ZeroCopySend>(FileBuilder<'b, T>);

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConcept for OwnerOnlyFile<T> {
    fn name(&self) -> &FileName {
        self.0.name()
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptMgmt for OwnerOnlyFile<T> {
    type Configuration = <File<T> as NamedConceptMgmt>::Configuration;

    unsafe fn remove_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptRemoveError> {
        // SAFETY: the caller's contract is the one of the storage delegated to.
        unsafe { File::<T>::remove_cfg(name, cfg) }
    }
    fn does_exist_cfg(
        name: &FileName,
        cfg: &Self::Configuration,
    ) -> Result<bool, NamedConceptDoesExistError> {
        File::<T>::does_exist_cfg(name, cfg)
    }
    fn list_cfg(cfg: &Self::Configuration) -> Result<Vec<FileName>, NamedConceptListError> {
        File::<T>::list_cfg(cfg)
    }
    fn remove_path_hint(value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        File::<T>::remove_path_hint(value)
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> Abandonable for OwnerOnlyFile<T> {
    unsafe fn abandon_in_place(mut this: NonNull<Self>) {
        // SAFETY: the caller's contract, passed on to the one field.
        unsafe { File::<T>::abandon_in_place(NonNull::from_mut(&mut this.as_mut().0)) };
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> DynamicStorage<T> for OwnerOnlyFile<T> {
    type Builder<'b> = OwnerOnlyBuilder<'b, T>;

    fn does_support_persistency() -> bool {
        File::<T>::does_support_persistency()
    }
    fn has_ownership(&self) -> bool {
        self.0.has_ownership()
    }
    fn release_ownership(&self) {
        self.0.release_ownership()
    }
    fn acquire_ownership(&self) {
        self.0.acquire_ownership()
    }
    fn get(&self) -> &T {
        self.0.get()
    }
    fn default_suffix() -> FileName {
        File::<T>::default_suffix()
    }
    unsafe fn __internal_set_type_name_in_config(config: &mut Self::Configuration, name: &str) {
        // SAFETY: delegated unchanged.
        unsafe { File::<T>::__internal_set_type_name_in_config(config, name) }
    }
}

impl<T: Debug + Send + Sync + ZeroCopySend> NamedConceptBuilder<OwnerOnlyFile<T>>
    for OwnerOnlyBuilder<'_, T>
{
    fn new(name: &FileName) -> Self {
        OwnerOnlyBuilder(FileBuilder::<T>::new(name).enable_global_access(false))
    }
    fn config(self, config: &<OwnerOnlyFile<T> as NamedConceptMgmt>::Configuration) -> Self {
        OwnerOnlyBuilder(self.0.config(config))
    }
}

impl<'b, T: Debug + Send + Sync + ZeroCopySend> DynamicStorageBuilder<'b, T, OwnerOnlyFile<T>>
    for OwnerOnlyBuilder<'b, T>
{
    fn has_ownership(self, value: bool) -> Self {
        OwnerOnlyBuilder(self.0.has_ownership(value))
    }
    /// Ignored: the file stays owner-only (the reason this type exists).
    fn enable_global_access(self, _value: bool) -> Self {
        self
    }
    fn supplementary_size(self, value: usize) -> Self {
        OwnerOnlyBuilder(self.0.supplementary_size(value))
    }
    fn timeout(self, value: Duration) -> Self {
        OwnerOnlyBuilder(self.0.timeout(value))
    }
    fn initializer<F: FnMut(&mut MaybeUninit<T>, &mut BumpAllocator) -> bool + 'b>(
        self,
        value: F,
    ) -> Self {
        OwnerOnlyBuilder(self.0.initializer(value))
    }
    fn create(self) -> Result<OwnerOnlyFile<T>, DynamicStorageCreateError> {
        self.0.create().map(OwnerOnlyFile)
    }
    fn open(self, access_mode: AccessMode) -> Result<OwnerOnlyFile<T>, DynamicStorageOpenError> {
        self.0.open(access_mode).map(OwnerOnlyFile)
    }
    fn open_or_create(self) -> Result<OwnerOnlyFile<T>, DynamicStorageOpenOrCreateError> {
        self.0.open_or_create().map(OwnerOnlyFile)
    }
}

/// The content of iceoryx2's global management file, its node counter: the layout of
/// `iceoryx2::node::global_management_segment::State`, which iceoryx2 keeps private.
#[derive(Debug, Default)]
#[repr(C)]
struct NodeCounter {
    node_counter: core::sync::atomic::AtomicU32,
}

// SAFETY: one atomic integer and no pointer: valid in every process that maps it.
unsafe impl ZeroCopySend for NodeCounter {}

type PlainFile<T> = dynamic_storage::posix_shared_memory::Storage<T>;
type PlainBuilder<'b, T> = dynamic_storage::posix_shared_memory::Builder<'b, T>;
type PlainConfig = <PlainFile<NodeCounter> as NamedConceptMgmt>::Configuration;

/// The type name iceoryx2 gives its global file's content: the file name carries its hash, so
/// the file vic makes must carry the same one as the file the plain `ipc` service opens.
const ICEORYX2_COUNTER_TYPE: &str = "iceoryx2::node::global_management_segment::State";

/// The storage configuration and name of the plain `ipc` service's global file, as iceoryx2
/// makes them (`GlobalManagementSegment::dynamic_storage_config`).
fn plain_global_storage(cfg: &iceoryx2::config::Config) -> Result<(PlainConfig, FileName), String> {
    use iceoryx2::prelude::SemanticString;
    use iceoryx2_cal::named_concept::NamedConceptConfiguration;
    let v = iceoryx2_bb_elementary::package_version::PackageVersion::get();
    let mut suffix = cfg.global.node.global_mgmt_suffix;
    suffix
        .insert_bytes(
            0,
            format!(".{}_{}_{}", v.major(), v.minor(), v.patch()).as_bytes(),
        )
        .map_err(|e| format!("{e:?}"))?;
    let mut storage = PlainConfig::default()
        .prefix(&cfg.global.prefix)
        .suffix(&suffix)
        .path_hint(cfg.global.root_path());
    // SAFETY: sets the name whose hash names the file, before any use of the configuration:
    // iceoryx2's own (the layout of `NodeCounter` is that type's).
    unsafe {
        <PlainFile<NodeCounter> as DynamicStorage<NodeCounter>>::__internal_set_type_name_in_config(
            &mut storage,
            ICEORYX2_COUNTER_TYPE,
        )
    };
    let name = FileName::new(b"node").map_err(|e| format!("{e:?}"))?;
    Ok((storage, name))
}

/// The path of the plain `ipc` service's global management file in `/dev/shm`
/// (`{prefix}{sha1 of the type name}_node.{major}_{minor}_{patch}.global_mgmt`).
pub(super) fn plain_global_file(
    cfg: &iceoryx2::config::Config,
) -> Result<std::path::PathBuf, String> {
    use iceoryx2_cal::named_concept::NamedConceptConfiguration;
    let (storage, name) = plain_global_storage(cfg)?;
    Ok(std::path::Path::new("/dev/shm").join(storage.path_for(&name).file_name().to_string()))
}

/// Creates the global management file of iceoryx2's plain `ipc` service (the one client
/// that uses it: the Python bindings, which offer no other service type) owner-only, 0600 from
/// its creation on, unless it exists. The plain service opens an existing file and creates a
/// missing one world-writable (0666): so the Python client opens only a file a vic process made
/// (`python/vic_client` refuses to connect while it is missing, foreign or not owner-only), and
/// no other user ever gets a moment to open it. An existing file is left as it is (the caller
/// narrows the namespace's files in `/dev/shm` next).
pub(super) fn create_plain_global_file(cfg: &iceoryx2::config::Config) -> Result<(), String> {
    let (storage, name) = plain_global_storage(cfg)?;
    <PlainBuilder<'_, NodeCounter> as NamedConceptBuilder<PlainFile<NodeCounter>>>::new(&name)
        .config(&storage)
        .has_ownership(false)
        .timeout(cfg.global.creation_timeout)
        .enable_global_access(false)
        .initializer(|v, _| {
            v.write(NodeCounter::default());
            true
        })
        .open_or_create()
        .map(drop)
        .map_err(|e| format!("{e:?}"))
}
